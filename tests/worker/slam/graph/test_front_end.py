"""The front end's match: the hill climb keeps to the search window, and the innovation gate
takes the best match the odometry allows when the scan fits it nearly as well."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.slam.graph.worlds import box_points, to_map
from tests.worker.slam.helpers import Laser, box_scan
from worker.slam.graph.matcher import MatchResult, PointMap, angular_step
from worker.slam.graph.params import GraphSlamParams
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

LASER = Laser()
BOX = (0.0, 0.0, 8.0, 5.0)


def _points(pose):
    return box_points(pose, LASER, BOX)


@pytest.mark.parametrize("half", [0.1, 0.2])
def test_the_hill_climb_stays_in_the_angular_window(half):
    # the scan's true heading is 0.3 rad from the prior: a window of +-0.1 or +-0.2 rad
    # must not return it (the climb from the window's edge would reach it unbounded)
    a = np.array([4.0, 2.5, 0.0])
    b = np.array([4.0, 2.5, 0.3])
    pm = PointMap(to_map(a, _points(a)), 0.05, 0.1, 5)
    res = pm.match(_points(b), a, 0.25, half, 0.1)
    step = angular_step(_points(b), 0.05)  # the search's angles: whole steps, rounded up
    assert abs(res.pose[2] - a[2]) <= np.ceil(half / step) * step + 1e-9 < 0.3 - 0.05
    wide = pm.match(_points(b), a, 0.25, 0.349, 0.1)
    assert wide.pose[2] == pytest.approx(0.3, abs=0.01)


def test_the_hill_climb_stays_in_the_linear_window():
    a = np.array([4.0, 2.5, 0.0])
    b = np.array([4.4, 2.7, 0.0])  # 0.4 m and 0.2 m from the prior
    pm = PointMap(to_map(a, _points(a)), 0.05, 0.1, 5)
    res = pm.match(_points(b), a, 0.15, 0.349, 0.1)
    assert abs(res.pose[0] - a[0]) <= 0.15 + 1e-9 and abs(res.pose[1] - a[1]) <= 0.15 + 1e-9


class _Scripted:
    """Stands in for GraphSlam._link_match: the i-th call answers answers[i] (the last one
    for any call after); records the windows asked for."""

    def __init__(self, *answers: MatchResult):
        self.answers, self.windows = answers, []

    def __call__(self, idx, points, prior, poses=None, prior_information=None, window=None):
        self.windows.append(window)
        return self.answers[min(len(self.windows), len(self.answers)) - 1]


def _second_node(graph: GraphSlamParams, far_score: float, *answers: MatchResult):
    """The second node's match scripted: the full window finds a pose turned 0.25 rad
    (chi^2 625 under the odometry's sigmas 0.06 m, 0.01 rad), then `answers` in turn, or
    one 0.01 m and 0.01 rad from the prediction scoring `far_score` if a float is given."""
    slam = make_slam("graph", LASER, SlamParams(graph=graph))
    p0 = np.array([4.0, 2.5, 0.0])
    slam.process(0.0, p0, box_scan(p0, LASER.angles, BOX))
    p1 = np.array([4.6, 2.5, 0.0])  # odometry: 0.6 m ahead, no turn (sigmas 0.06 m, 0.01 rad)
    far = MatchResult(np.array([4.6, 2.5, 0.25]), far_score)
    script = _Scripted(far, *answers)
    slam._link_match = script
    slam.process(0.1, p1, box_scan(p1, LASER.angles, BOX))
    return slam, script


def _near(score: float) -> MatchResult:
    return MatchResult(np.array([4.61, 2.5, 0.01]), score)  # chi^2 1/36 + 1 from the prediction


def test_a_match_the_odometry_rules_out_gives_way_to_one_nearly_as_good_within_the_gate():
    slam, script = _second_node(GraphSlamParams(), 0.60, _near(0.56))  # >= 0.9 * 0.60
    assert slam.nodes.poses[1] == pytest.approx([4.61, 2.5, 0.01])
    assert slam.gated_matches == 1
    # the window asked: sqrt(16.27) sigmas of the odometry (0.06 m, 0.01 rad)
    lin, ang = script.windows[1]
    assert lin == pytest.approx(np.sqrt(16.27) * 0.06) and ang == pytest.approx(
        np.sqrt(16.27) * 0.01
    )
    assert len(script.windows) == 2  # the gated match is inside the gate: no third search


def test_a_gated_match_still_outside_the_gate_is_searched_for_inside_it():
    # the box around the gate's ellipsoid (+-4.03 sigma per axis) holds poses the gate rules
    # out: 3 sigmas ahead and 3 sigmas turned is chi^2 18 > 16.27 (office_c seed 2: a room
    # that fitted 0.12 m and 0.23 rad off drew a wall across a door). Then the box inside
    # the ellipsoid (+-sqrt(16.27 / 3) = 2.33 sigma) is searched, and its best taken
    corner = MatchResult(np.array([4.6 + 3 * 0.06, 2.5, 3 * 0.01]), 0.59)
    slam, script = _second_node(GraphSlamParams(), 0.60, corner, _near(0.56))
    assert slam.nodes.poses[1] == pytest.approx([4.61, 2.5, 0.01])
    assert len(script.windows) == 3
    lin, ang = script.windows[2]
    inner = np.sqrt(16.27 / 3)
    assert lin == pytest.approx(inner * 0.06) and ang == pytest.approx(inner * 0.01)


def test_the_scans_evidence_wins_when_the_gated_match_fits_clearly_worse():
    slam, _ = _second_node(GraphSlamParams(), 0.60, _near(0.50))  # 0.50 < 0.9 * 0.60
    assert slam.nodes.poses[1] == pytest.approx([4.6, 2.5, 0.25])
    assert slam.gated_matches == 0


def test_with_the_gate_off_the_first_match_stands():
    slam, script = _second_node(GraphSlamParams(link_gate_chi2=0.0), 0.60, _near(0.59))
    assert slam.nodes.poses[1] == pytest.approx([4.6, 2.5, 0.25])
    assert script.windows == [None]
