"""Recovery: the trail kept for backing out, the back-out command, the footprint's gap."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.explore.flat_params import explore_params
from worker.explore.navigator import Navigator
from worker.explore.params import ExploreParams
from worker.explore.recovery import Trail, back_out, square_gap

RES = 0.05


def test_trail_keeps_points_spaced_and_drops_the_oldest_past_its_cap():
    # binary fractions of a metre, exact in floating point: a point every 4th step
    trail = Trail(explore_params(trail_spacing=1 / 16, trail_cap=10, trail_trim=4).recovery)
    for i in range(13):
        trail.grow(np.array([i / 64, 0.0, 0.0]))
    assert [float(q[0]) for q in trail.points] == [0.0, 1 / 16, 2 / 16, 3 / 16]
    trail = Trail(explore_params(trail_spacing=0.05, trail_cap=10, trail_trim=4).recovery)
    for i in range(11):  # the 11th point passes the cap: the 4 oldest go, 7 remain
        trail.grow(np.array([0.1 * i, 0.0, 0.0]))
    assert len(trail.points) == 7
    assert trail.points[0][0] == pytest.approx(0.4)


def test_back_target_lies_the_retrace_distance_back_in_a_straight_line():
    p = explore_params(retrace_min_points=4, retrace_points=16, trail_spacing=0.05)
    trail = Trail(p.recovery)
    for i in range(3):
        trail.grow(np.array([0.1 * i, 0.0, 0.0]))
    assert trail.back_target() is None  # 3 points: too short
    for i in range(3, 20):
        trail.grow(np.array([0.1 * i, 0.0, 0.0]))
    # newest point at 1.9 m: the newest one at least 16 x 0.05 = 0.8 m from it is at 1.1 m
    assert trail.back_target()[0] == pytest.approx(1.1)
    trail = Trail(p.recovery)
    for i in range(5):
        trail.grow(np.array([0.1 * i, 0.0, 0.0]))
    assert trail.back_target()[0] == 0.0  # nothing 0.8 m away: the trail's start


def test_back_out_after_dithering_goes_the_way_the_robot_came_and_further_each_time():
    # in along x to 2 m, then 40 periods of dithering on the spot (trail points 0.06 m apart)
    p = explore_params(retrace_min_points=4, retrace_points=16, trail_spacing=0.05)
    trail = Trail(p.recovery)
    for i in range(41):
        trail.grow(np.array([0.05 * i, 0.0, 0.0]))
    for k in range(40):
        trail.grow(np.array([2.0, 0.06 * (k % 2), 0.0]))
    here = np.array([2.0, 0.0])
    # counted in points, 16 back would be a dithering point where the robot stands
    assert np.hypot(*(trail.points[-17] - here)) < 0.1
    first = trail.back_target(here)
    assert first[1] == 0.0 and first[0] == pytest.approx(1.2)  # 0.8 m back along the way in
    # backing out appends the robot's positions; the back-out ends at its target
    for x in (1.9, 1.6, 1.3, 1.2):
        trail.grow(np.array([x, 0.0, 0.0]))
    trail.cut_to(first)
    assert trail.points[-1][0] == pytest.approx(1.2)
    second = trail.back_target(first)
    assert second[0] == pytest.approx(0.4)  # the next back-out goes on, 0.8 m further
    trail.points = trail.points[10:]  # trimmed past the cap: the target is gone
    trail.cut_to(np.array([0.1, 0.0]))
    assert trail.points == []


def _free_local(pose):
    p = ExploreParams()
    nav = Navigator(p, np.linspace(-2.35, 2.35, 541), 30.0)
    nav.update_map(np.full((80, 80), 0.05, dtype=np.float32), RES, (0.0, 0.0), True)
    nav.local.build(pose[0], pose[1], nav.costmap, pose[2])
    return p, nav.local


def test_back_out_reverses_straight_to_a_target_behind():
    pose = np.array([2.0, 2.0, 0.0])
    p, local = _free_local(pose)
    # target 1 m behind: the rear already points at it, so reverse at 1.5 x escape_vel
    v, w = back_out(p.recovery, p.dwa, local, pose, np.array([-1.0, 0.0]))
    assert (v, w) == (pytest.approx(-0.15), 0.0)


def test_back_out_first_turns_the_rear_towards_a_target_at_the_side():
    pose = np.array([2.0, 2.0, 0.0])
    p, local = _free_local(pose)
    # target to the left (+y): the rear (pointing -x) must turn by -90 degrees, clockwise;
    # 1.5 x 90 degrees is past max_vel_theta, and the error is past 0.6 rad: turn only
    v, w = back_out(p.recovery, p.dwa, local, pose, np.array([0.0, 1.0]))
    assert (v, w) == (0.0, -p.dwa.max_vel_theta)


def test_back_out_into_an_obstacle_is_not_legal():
    pose = np.array([2.0, 2.0, 0.0])
    p, local = _free_local(pose)
    # scan hits 3 cm behind the footprint's rear edge (x = 1.8): 7.5 cm of reversing hit them
    local.add_points(0.0, np.column_stack((np.full(21, 1.77), np.linspace(1.5, 2.5, 21))))
    local.build(pose[0], pose[1], None, pose[2], use_map=False)
    assert back_out(p.recovery, p.dwa, local, pose, np.array([-1.0, 0.0])) is None


def test_square_gap_is_the_distance_to_the_footprints_edge():
    px = np.array([0.5, 0.3, 0.1])
    py = np.array([0.0, 0.3, 0.0])
    # unit test by hand: half side 0.2 at the origin; (0.5, 0) is 0.3 from the edge x = 0.2
    assert square_gap(px[:1], py[:1], 0.0, 0.0, 0.0, 0.2) == pytest.approx(0.3)
    # (0.3, 0.3) is 0.1 off in x and y: from the corner sqrt(0.02)
    assert square_gap(px[1:2], py[1:2], 0.0, 0.0, 0.0, 0.2) == pytest.approx(math.sqrt(0.02))
    assert square_gap(px, py, 0.0, 0.0, 0.0, 0.2) == 0.0  # (0.1, 0) is inside
    # turned by 45 degrees the corner points along x: (0.5, 0) is 0.5 - 0.2 sqrt(2) away
    gap = square_gap(px[:1], py[:1], 0.0, 0.0, math.pi / 4, 0.2)
    assert gap == pytest.approx(0.5 - 0.2 * math.sqrt(2))


def _gap_local(gap_lo: float, gap_hi: float, pose):
    """A local costmap of a 4 m x 4 m map with a wall at x 2.0-2.1 m, open between y = gap_lo
    and gap_hi [m] (the cells whose centres lie between them)."""
    p = ExploreParams()
    nav = Navigator(p, np.linspace(-2.35, 2.35, 541), 30.0)
    prob = np.full((80, 80), 0.05, dtype=np.float32)
    ys = (np.arange(80) + 0.5) * RES
    wall = (ys < gap_lo) | (ys > gap_hi)
    prob[wall, 40:42] = 0.95
    nav.update_map(prob, RES, (0.0, 0.0), True)
    nav.local.build(pose[0], pose[1], nav.costmap, pose[2], use_map=True)
    return p, nav.local


def _straight_trail(x1: float, planned=lambda x: True) -> Trail:
    """A trail along y = 2 m from x = 0 to x1, a point every 0.05 m (all kept), heading +x."""
    trail = Trail(explore_params(trail_spacing=0.04).recovery)
    for i in range(int(round(x1 / 0.05)) + 1):
        x = 0.05 * i
        trail.grow(np.array([x, 2.0, 0.0]), planned(x))
    return trail


def test_a_trap_is_a_gap_behind_the_robot_now_narrower_than_its_body():
    pose = np.array([2.6, 2.0, 0.0])
    # the robot drove along y = 2 through the wall's gap; 0.6 m wide, the footprint (0.4 m)
    # fits at every pose it drove through: no trap
    _, local = _gap_local(1.7, 2.3, pose)
    trail = _straight_trail(2.6)
    assert trail.closed_behind(local, 1.0) is None
    # the same gap as the map draws it once seen from the far side, 0.3 m (cells 1.85-2.15
    # m free): the footprint at x overlaps the wall (x 2.0-2.1) once its front edge x + 0.2
    # is past 2.0: first at x = 1.85. The way out: the newest trail point at least
    # half + reach = 1.2 m before it, x = 0.65
    _, local = _gap_local(1.85, 2.15, pose)
    out = trail.closed_behind(local, 1.0)
    assert out is not None and out[0] == pytest.approx(0.65) and out[1] == 2.0
    # dealt with once: the same stretch does not make every goal after it a trap again
    trail.unchecked()
    assert trail.closed_behind(local, 1.0) is None
    # a stretch the local planner did not drive forwards (a back-off, a turn in contact)
    # says nothing of the gap: its poses were never checked with the padding
    trail = _straight_trail(2.6, planned=lambda x: abs(x - 2.3) > 0.01)
    assert trail.closed_behind(local, 1.0) is None
    # a trail that has not reached the gap yet: nothing behind it overlaps the wall
    trail = _straight_trail(1.8)
    assert trail.closed_behind(local, 1.0) is None
    # a gap 0.5 m wide: the robot keeps 5 cm each side: no trap
    _, local = _gap_local(1.75, 2.25, pose)
    assert _straight_trail(2.6).closed_behind(local, 1.0) is None


def test_the_back_out_steers_along_the_trail_round_its_bends():
    # in along x to (1, 0), then up to (1, 1): backing out from (1, 1) to the start of the
    # trail, the aim is on the way in (x = 1, lower y), not on the straight line to (0, 0)
    p = explore_params(trail_spacing=0.04)  # every point below kept (0.05 m apart)
    trail = Trail(p.recovery)
    for i in range(21):
        trail.grow(np.array([0.05 * i, 0.0, 0.0]))
    for i in range(1, 21):
        trail.grow(np.array([1.0, 0.05 * i, math.pi / 2]))
    target = trail.points[0]
    aim = trail.carrot(np.array([1.0, 1.0]), target, 0.25)
    assert aim[0] == pytest.approx(1.0) and aim[1] == pytest.approx(0.75)
    # past the bend, the aim is on the first leg
    aim = trail.carrot(np.array([1.0, 0.1]), target, 0.25)
    assert aim[1] == 0.0 and aim[0] == pytest.approx(0.75)  # hypot(0.25, 0.1) >= 0.25
    # near the target: the target itself
    assert np.array_equal(trail.carrot(np.array([0.1, 0.0]), target, 0.25), target)
