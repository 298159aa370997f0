"""Doors under the planner's margin but wider than the robot: navfn's rule as a fallback."""

from __future__ import annotations

import numpy as np
import pytest

from worker.explore.costmap import GlobalCostmap
from worker.explore.frontiers import FrontierSearch
from worker.explore.params import ExploreParams
from worker.explore.planner import GlobalPlanner, narrow_params, planner_blocked_cost

RES = 0.05


def _door(cells: int) -> np.ndarray:
    """(60, 100) SLAM probabilities: a wall at x = 50 with a door of `cells` free cells."""
    prob = np.full((60, 100), 0.05)
    prob[:, 50] = 0.9
    prob[30 - cells // 2 : 30 - cells // 2 + cells, 50] = 0.05
    return prob


def _costmap(prob: np.ndarray, p: ExploreParams) -> GlobalCostmap:
    cm = GlobalCostmap(p)
    cm.update(prob.astype(np.float32), RES, (0.0, 0.0))
    return cm


def _far_room_search(p: ExploreParams, closed) -> tuple[FrontierSearch, GlobalCostmap]:
    """A frontier search over a 10-cell door whose far room is known up to x = 4 m."""
    prob = _door(10)
    prob[:, 80:] = np.nan
    cm = _costmap(prob, p)
    fs = FrontierSearch(p, closed)
    fs.update(cm, None)
    return fs, cm


def test_a_0_7_m_door_mapped_a_cell_narrower_each_side_is_planned_through():
    # 0.7 m in the floorplan, 0.5 m (10 cells) in the map: the door's middle cells are 5 and
    # 6 cells (0.25, 0.30 m) from the jambs' centres; one of them at 0.25 m, under the 0.2 m
    # inscribed radius plus the 0.1 m margin, but over the inscribed radius alone
    p = ExploreParams()
    path = GlobalPlanner(p).plan(_costmap(_door(10), p), (0.5, 0.5), (4.5, 0.5))
    assert path is not None
    crossing = path[np.argmin(np.abs(path[:, 0] - 2.525))]
    assert 25 * RES < crossing[1] < 35 * RES
    # without the fallback (narrow margin = the margin) there is no plan
    strict = ExploreParams(narrow_margin=p.planner_margin)
    assert GlobalPlanner(strict).plan(_costmap(_door(10), strict), (0.5, 0.5), (4.5, 0.5)) is None


def test_the_fallback_is_navfn_and_still_refuses_a_door_narrower_than_the_robot():
    p = ExploreParams()
    from worker.explore.costmap_kernels import INSCRIBED

    assert planner_blocked_cost(narrow_params(p)) == INSCRIBED
    assert narrow_params(p).footprint_half_m == p.footprint_half_m
    # 0.35 m mapped (7 cells): the middle cell is 0.2 m from a jamb, inside the inscribed radius
    assert GlobalPlanner(p).plan(_costmap(_door(7), p), (0.5, 0.5), (4.5, 0.5)) is None


@pytest.mark.parametrize(
    ("cells", "narrow_margin", "expected"), [(10, 0.0, True), (10, 0.1, False), (7, 0.0, False)]
)
def test_a_frontier_behind_a_narrow_door_is_a_goal(cells, narrow_margin, expected):
    prob = _door(cells)
    # the far room known up to x = 4 m: every goal (within 0.6 m of the frontier) lies past
    # the wall, so the goal search must get through the door
    prob[:, 80:] = np.nan
    p = ExploreParams(narrow_margin=narrow_margin)
    cm = _costmap(prob, p)
    fs = FrontierSearch(p)
    fs.update(cm, None)
    goal = fs.choose(cm, (0.5, 1.5), [])
    if expected:
        assert goal is not None and goal.goal_xy[0] > 3.3
    else:
        assert goal is None


def test_a_narrow_gap_the_robot_failed_to_pass_is_closed_to_the_fallback_until_cleared():
    p = ExploreParams()
    cm = _costmap(_door(10), p)
    planner = GlobalPlanner(p)
    path = planner.plan(cm, (0.5, 0.5), (4.5, 0.5))
    assert path is not None
    # the robot stood 0.3 m before the door (x = 2.5 m) and got no further: the door's
    # cells on its plan within 1 m are the ones under the margin's blocked cost
    robot = (2.2, 1.5)
    n = planner.closed.close(cm, p, path, robot, p.closed_gap_radius)
    blocked = planner_blocked_cost(p)
    on_plan = [
        cm.inflated[cm.world_to_cell(*q)[::-1]] for q in path if np.hypot(*(q - robot)) <= 1.0
    ]
    assert n == sum(1 for c in on_plan if c >= blocked) > 0
    before = cm.inflated.copy()
    assert planner.plan(cm, (0.5, 0.5), (4.5, 0.5)) is None  # the only way is closed
    np.testing.assert_array_equal(cm.inflated, before)  # and the costmap is left as it was
    # the frontier search's fallback sees the same closed door
    fs, cm2 = _far_room_search(p, planner.closed)
    assert fs.choose(cm2, (0.5, 1.5), []) is None
    planner.closed.clear()  # the blacklist's retry opens it again
    assert planner.plan(cm, (0.5, 0.5), (4.5, 0.5)) is not None
    assert fs.choose(cm2, (0.5, 1.5), []) is not None


def test_a_closed_gap_stays_closed_to_the_escapes_after_the_back_out():
    """Histor4 (issue 18): the robot backed out of a 0.5 m door and drove back to it goal
    after goal until the stuck rule fired: the plans that may escape near the robot (0.5 m;
    1.5 m from a pocket) crossed the closed cells, and the closure was the failed plan's
    line only, a cell beside which the next plan slipped through. Now the whole gap is
    closed, to every attempt; a robot standing in it can still leave."""
    p = ExploreParams()
    cm = _costmap(_door(10), p)
    planner = GlobalPlanner(p)
    path = planner.plan(cm, (0.5, 0.5), (4.5, 0.5))
    planner.closed.close(cm, p, path, (2.2, 1.5), p.closed_gap_radius)
    # closed: every cell of the door's throat under the inscribed cost (rows 28-31 of the
    # wall's column; the failed plan crossed row 29)
    with planner.closed.applied(cm):
        assert (cm.inflated[27:33, 50] >= 253).all()
    # backed out to 0.8 m before the door: the door is within the pocket escape's 1.5 m,
    # and within the 0.5 m escape of a plan from 0.3 m further on
    for start in ((1.7, 1.5), (2.0, 1.4)):
        assert planner.plan(cm, start, (4.5, 1.5)) is None, start
    # the frontier search sees the same
    fs, cm2 = _far_room_search(p, planner.closed)
    assert fs.choose(cm2, (1.7, 1.5), []) is None
    # standing in the closed door, the robot is planned out of it, back to its own side
    back = planner.plan(cm, (2.525, 1.5), (0.5, 1.5))
    assert back is not None and back[-1][0] < 0.6
