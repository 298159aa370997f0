"""Safety controller: obstacle ahead within 0.2 m of the footprint -> back off, turn away."""

from __future__ import annotations

import math

import numpy as np

from worker.explore.params import ExploreParams
from worker.explore.safety import SafetyController, front_clearance

ANGLES = -3 * math.pi / 4 + np.arange(541) * math.pi / 360


def _scan_with_point(x, y):
    """A scan seeing nothing but one point (x, y) in the robot frame."""
    ranges = np.full(541, 30.0)
    a = math.atan2(y, x)
    k = int(round((a - ANGLES[0]) / (math.pi / 360)))
    ranges[k] = math.hypot(x, y)
    return ranges


def test_front_clearance_measures_from_the_front_edge_in_the_robots_way():
    d, side = front_clearance(_scan_with_point(0.35, 0.05), ANGLES, 30.0, 0.2, 0.02)
    assert abs(d - 0.15) < 2e-3 and side == 1.0
    d, side = front_clearance(_scan_with_point(0.3, -0.21), ANGLES, 30.0, 0.2, 0.02)
    assert abs(d - 0.1) < 5e-3 and side == -1.0
    d, _ = front_clearance(_scan_with_point(0.3, 0.3), ANGLES, 30.0, 0.2, 0.02)
    assert d == math.inf  # a door jamb beside the robot's way, not in it
    d, _ = front_clearance(_scan_with_point(0.0, 0.25), ANGLES, 30.0, 0.2, 0.02)
    assert d == math.inf  # beside the robot, not ahead


def test_safety_backs_off_and_turns_away_then_releases():
    p = ExploreParams()
    safety = SafetyController(p.safety, p.costmap, p.dwa, ANGLES, 30.0)
    assert safety.check(0.0, _scan_with_point(1.0, 0.0), 0.5) is None
    v, w = safety.check(0.0, _scan_with_point(0.3, 0.1), 0.5)  # obstacle front-left
    assert v == p.dwa.escape_vel < 0 and w < 0  # nose turns clockwise, away from the left
    assert safety.n_triggers == 1 and safety.active(0.5)
    assert safety.check(0.5, _scan_with_point(5.0, 0.0), 0.5) == (v, w)  # manoeuvre continues
    assert safety.check(1.0, _scan_with_point(5.0, 0.0), 0.5) is None
    assert safety.check(1.1, _scan_with_point(0.3, -0.1), 0.0) is None  # not moving forwards
    _, w = safety.check(1.2, _scan_with_point(0.3, -0.1), 0.3)  # front-right: turn left
    assert w > 0


def test_on_a_noisy_laser_one_short_reading_is_not_an_obstacle_two_beams_are():
    # a wall 0.7 m ahead (0.5 m from the footprint's front) and one reading of it 0.45 m
    # short, as 0.1 m range noise gives now and then: the raw controller backs off, the
    # median of three beams (what Navigator uses on a noisy laser) does not; a thin leg
    # 0.3 m ahead seen by two neighbouring beams (7 mm apart there) stops both
    p = ExploreParams()
    assert p.safety.safety_median_beams == 3
    wall = np.full(541, 30.0)
    ahead = np.abs(ANGLES) < 0.3
    wall[ahead] = 0.7 / np.cos(ANGLES[ahead])
    k = int(np.argmin(np.abs(ANGLES)))
    short = wall.copy()
    short[k] = 0.25
    raw = SafetyController(p.safety, p.costmap, p.dwa, ANGLES, 30.0)
    filtered = SafetyController(p.safety, p.costmap, p.dwa, ANGLES, 30.0, median=3)
    assert raw.check(0.0, wall, 0.5) is None and filtered.check(0.0, wall, 0.5) is None
    assert raw.check(0.0, short, 0.5) is not None
    assert filtered.check(0.0, short, 0.5) is None
    leg = wall.copy()
    leg[k : k + 2] = 0.3
    assert (
        SafetyController(p.safety, p.costmap, p.dwa, ANGLES, 30.0, median=3).check(0.0, leg, 0.5)
        is not None
    )


def test_the_navigator_filters_only_a_noisy_lasers_readings():
    from worker.explore.navigator import Navigator

    p = ExploreParams()
    assert Navigator(p, ANGLES, 30.0).safety.median == 1
    assert Navigator(p, ANGLES, 30.0, range_noise=0.1).safety.median == 3


def test_front_clearance_slack_and_min_points_as_bench_safety_scores_them():
    # Hand-placed: a hit at 45 degrees, (0.22, 0.21) in the robot frame, lies in the band
    # (|y| < 0.22) 0.02 m ahead of the front; 0.1 m farther along its beam it would be at
    # (0.29, 0.28), beside the band: with slack 0.1 it is not in the way. A hit straight
    # ahead 0.15 m from the front moves along x only and stays.
    side = _scan_with_point(0.22, 0.21)
    d, _ = front_clearance(side, ANGLES, 30.0, 0.2, 0.02)
    assert abs(d - 0.02) < 5e-3
    assert front_clearance(side, ANGLES, 30.0, 0.2, 0.02, slack=0.1)[0] == math.inf
    ahead = _scan_with_point(0.35, 0.0)
    d, _ = front_clearance(ahead, ANGLES, 30.0, 0.2, 0.02, slack=0.1)
    assert abs(d - 0.15) < 2e-3
    # min_points: the n-th nearest hit in the way; fewer hits than that, nothing
    both = ahead.copy()
    k = int(np.argmax(ahead < 30.0))
    both[k + 1] = 0.5  # a second hit, 0.3 m ahead of the front
    assert front_clearance(ahead, ANGLES, 30.0, 0.2, 0.02, min_points=2)[0] == math.inf
    d, _ = front_clearance(both, ANGLES, 30.0, 0.2, 0.02, min_points=2)
    assert abs(d - 0.3) < 2e-3
