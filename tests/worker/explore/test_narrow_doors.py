"""Doors under the planner's margin but wider than the robot: navfn's rule as a fallback."""

from __future__ import annotations

import numpy as np
import pytest

from worker.explore.costmap import GlobalCostmap
from worker.explore.flat_params import explore_params
from worker.explore.frontiers import FrontierSearch
from worker.explore.navigator import Navigator
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
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(prob.astype(np.float32), RES, (0.0, 0.0))
    return cm


def _far_room_search(p: ExploreParams, closed) -> tuple[FrontierSearch, GlobalCostmap]:
    """A frontier search over a 10-cell door whose far room is known up to x = 4 m."""
    prob = _door(10)
    prob[:, 80:] = np.nan
    cm = _costmap(prob, p)
    fs = FrontierSearch(p.frontiers, p.planner, closed)
    fs.update(cm, None)
    return fs, cm


def test_a_0_7_m_door_mapped_a_cell_narrower_each_side_is_planned_through():
    # 0.7 m in the floorplan, 0.6 m (12 cells) in the map: the door's middle cells are 6 and
    # 7 cells (0.30, 0.35 m) from the jambs' centres, the 0.2 m half side plus the 0.1 m
    # margin; 11 cells leave the same 0.30 m
    p = ExploreParams()
    for cells in (12, 11):
        path = GlobalPlanner(p.planner).plan(_costmap(_door(cells), p), (0.5, 0.5), (4.5, 0.5))
        assert path is not None
        crossing = path[np.argmin(np.abs(path[:, 0] - 2.525))]
        assert 24 * RES < crossing[1] < 36 * RES


def test_a_door_the_map_draws_0_5_m_wide_is_planned_through_only_by_the_last_pass():
    # 10 cells (0.5 m: a 0.5 m door, the robot's 0.4 m and 5 cm each side): the middle cells
    # are 0.25 m from a jamb's centre, under 0.2 + 0.06 m, over the 0.2 m inscribed radius
    p = ExploreParams()
    assert GlobalPlanner(p.planner).plan(_costmap(_door(10), p), (0.5, 0.5), (4.5, 0.5)) is None
    path = GlobalPlanner(p.planner).plan(
        _costmap(_door(10), p), (0.5, 0.5), (4.5, 0.5), squeeze=True
    )
    assert path is not None and path[-1][0] > 4.4
    # no last pass when its margin is the narrow one (the runs before it had only navfn's
    # rule as the fallback: narrow_margin 0)
    off = explore_params(squeeze_margin=p.planner.narrow_margin)
    assert (
        GlobalPlanner(off.planner).plan(_costmap(_door(10), off), (0.5, 0.5), (4.5, 0.5), True)
        is None
    )
    old = explore_params(narrow_margin=0.0)
    assert (
        GlobalPlanner(old.planner).plan(_costmap(_door(10), old), (0.5, 0.5), (4.5, 0.5))
        is not None
    )


def test_the_fallback_is_navfn_and_still_refuses_a_door_narrower_than_the_robot():
    p = ExploreParams()
    from worker.explore.costmap_kernels import INSCRIBED, inflation_cost

    assert planner_blocked_cost(narrow_params(p.planner, squeeze=True), p.costmap) == INSCRIBED
    # the narrow margin's: the cost at 0.26 m from an obstacle's centre, plus one
    cost = inflation_cost(0.26, 0.2, p.costmap.cost_scaling_factor, p.costmap.inflation_radius)
    assert planner_blocked_cost(narrow_params(p.planner), p.costmap) == cost + 1
    assert narrow_params(p.planner).planner_margin == p.planner.narrow_margin
    # 0.35 m mapped (7 cells): the middle cell is 0.2 m from a jamb, inside the inscribed radius
    assert (
        GlobalPlanner(p.planner).plan(_costmap(_door(7), p), (0.5, 0.5), (4.5, 0.5), True) is None
    )


def test_squeeze_margin_may_not_exceed_the_narrow_margin():
    from worker.errors import InputError

    with pytest.raises(InputError, match="squeeze_margin"):
        explore_params(squeeze_margin=0.07)


@pytest.mark.parametrize(
    ("cells", "squeeze", "expected"),
    [(12, False, "goal"), (10, False, None), (10, True, "squeeze"), (7, True, None)],
)
def test_a_frontier_behind_a_narrow_door_is_a_goal(cells, squeeze, expected):
    prob = _door(cells)
    # the far room known up to x = 4 m: every goal (within 0.6 m of the frontier) lies past
    # the wall, so the goal search must get through the door
    prob[:, 80:] = np.nan
    p = ExploreParams()
    cm = _costmap(prob, p)
    fs = FrontierSearch(p.frontiers, p.planner)
    fs.update(cm, None)
    goal = fs.choose(cm, (0.5, 1.5), [], squeeze=squeeze)
    if expected is None:
        assert goal is None
    else:
        assert goal is not None and goal.goal_xy[0] > 3.3
        assert goal.squeeze == (expected == "squeeze")


def _tight_room_and_a_far_frontier(far: bool) -> np.ndarray:
    """(120, 100): a wall at x = 2.5 m with a 10-cell door (y 1.25-1.75 m), the room past it
    known to x = 3.5 m; with `far`, unknown space past y = 5.8 m on the robot's side too."""
    prob = np.full((120, 100), 0.05)
    prob[:, 50] = 0.9
    prob[25:35, 50] = 0.05
    prob[:, 70:] = np.nan
    prob[116:, 50:] = 0.9
    if far:
        prob[116:, :50] = np.nan
    return prob.astype(np.float32)


def _first_goal(
    prob: np.ndarray, p: ExploreParams, pose=(0.9, 1.5, 0.0), blacklist=(), noise: float = 0.0
):
    nav = Navigator(p, np.linspace(-2.35, 2.35, 541), 30.0, noise)
    nav.update_map(prob, RES, (0.0, 0.0), True)
    nav.memory.blacklist.extend(np.array(b, dtype=float) for b in blacklist)
    cmd = nav.step(0.0, np.array(pose), 0.0, 0.0, np.full(541, 30.0))
    return nav, cmd


def test_a_room_behind_a_door_the_map_draws_0_5_m_wide_is_entered_last():
    """wilbraham (issue 18): with every frontier the margin reaches given up once, the
    narrow fallback took the robot into a classroom through a 0.5 m door at 1,120 s; it could
    not line up with the door again from inside, and the frontiers given up earlier (whose
    retry was still to come) were never reached. Such a door now waits for the rest."""
    p = explore_params(look_through_radius=0.0)
    far = _tight_room_and_a_far_frontier(far=True)
    # the far frontier (y 5.8 m) given up once: it is tried again before the door
    given_up = [(1.0, 5.775)]
    nav, _ = _first_goal(far, p, blacklist=given_up)
    assert nav.goal.goal_xy[1] > 5.0 and not nav.goal.squeeze
    # the fallback of the runs before (navfn's rule at once): the room, the retry left
    old = explore_params(look_through_radius=0.0, narrow_margin=0.0)
    nav, _ = _first_goal(far, old, blacklist=given_up)
    assert nav.goal.goal_xy[0] > 2.6 and len(nav.memory.blacklist) == 1
    # and so on a noisy laser, whose map draws doors narrower and whose stack takes every
    # door with the door passage: no squeeze pass
    nav, _ = _first_goal(far, p, blacklist=given_up, noise=0.1)
    assert nav.goal.goal_xy[0] > 2.6 and not nav.goal.squeeze
    # with nothing else left, the last pass takes the door (before the run is given up)
    nav, cmd = _first_goal(_tight_room_and_a_far_frontier(far=False), p)
    assert nav.goal.squeeze and nav.goal.goal_xy[0] > 2.6
    # off (squeeze_margin = narrow_margin): nothing is left
    off = explore_params(look_through_radius=0.0, squeeze_margin=p.planner.narrow_margin)
    nav, cmd = _first_goal(_tight_room_and_a_far_frontier(far=False), off)
    assert cmd.status == "no_frontier"
    # before it (look-through on, the default): a look through the door from this side
    nav, _ = _first_goal(_tight_room_and_a_far_frontier(far=False), ExploreParams())
    assert nav.goal.look_through and nav.goal.goal_xy[0] < 2.5


def test_a_goal_of_the_last_pass_takes_the_door_passage_on_a_noise_free_laser():
    p = explore_params(look_through_radius=0.0)
    assert not p.doors.door_align
    nav, cmd = _first_goal(_tight_room_and_a_far_frontier(far=False), p)
    assert nav.goal.squeeze
    # then 0.45 m before the door and 0.1 m off its axis, heading 0.6 rad off it: the
    # passage (off for the stack's other goals on a noise-free laser) has taken the door up
    # (centre (2.525, 1.5), axis +x) and turns the robot on the spot, to line it up
    for k in range(1, 4):
        cmd = nav.step(0.1 * k, np.array([2.05, 1.4, 0.6]), 0.0, 0.0, np.full(541, 30.0))
    door = nav.door.door
    assert door is not None and abs(door.centre[1] - 1.5) < 0.03 and door.axis[0] > 0.99
    assert cmd.status == "aligning" and cmd.v == 0.0 and cmd.w != 0.0
