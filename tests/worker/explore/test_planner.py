"""navfn-like planner: Dijkstra potentials, paths through gaps, unreachable goals, escaping."""

from __future__ import annotations

import math

import numpy as np

from worker.explore.costmap import GlobalCostmap
from worker.explore.params import ExploreParams
from worker.explore.planner import DijkstraSearch, GlobalPlanner, path_length

RES = 0.05


def _costmap(prob):
    cm = GlobalCostmap(ExploreParams())
    cm.update(prob.astype(np.float32), RES, (0.0, 0.0))
    return cm


def test_potential_on_open_ground_is_octile_distance_times_neutral_cost():
    cm = _costmap(np.full((41, 41), 0.05))
    target = np.zeros(cm.shape, dtype=bool)
    target[30, 35] = True
    search = DijkstraSearch()
    found = search.run(cm, (5, 10), target, ExploreParams())
    assert len(found) == 1 and found[0] == 30 * 41 + 35
    dx, dy = 30, 20  # 20 diagonal steps and 10 straight ones
    assert math.isclose(search.potential[30, 35], 50.0 * (10 + 20 * math.sqrt(2)), rel_tol=1e-12)
    assert math.isclose(search.potential_at(found)[0], 50.0 * (dx - dy + dy * math.sqrt(2)))


def test_path_goes_through_the_door_and_keeps_off_walls():
    prob = np.full((60, 100), 0.05)
    prob[:, 50] = 0.9
    prob[24:36, 50] = 0.05  # a 0.6 m door in the wall, cells 24..35
    cm = _costmap(prob)
    path = GlobalPlanner(ExploreParams()).plan(cm, (0.5, 0.5), (4.5, 0.5))
    assert path is not None
    crossing = path[np.argmin(np.abs(path[:, 0] - 2.525))]
    assert 24 * RES + 0.2 < crossing[1] < 36 * RES - 0.2  # through the door's middle part
    assert np.allclose(path[0], (0.525, 0.525)) and np.allclose(path[-1], (4.525, 0.525))
    # at least the straight lines up to the door's lowest passable point (y >= 1.4) and back
    assert path_length(path) > 2 * math.hypot(2.0, 0.9)


def test_goal_behind_a_closed_wall_is_unreachable():
    prob = np.full((60, 100), 0.05)
    prob[:, 50] = 0.9
    cm = _costmap(prob)
    assert GlobalPlanner(ExploreParams()).plan(cm, (0.5, 0.5), (4.5, 0.5)) is None


def test_door_narrower_than_the_robot_is_refused():
    prob = np.full((60, 100), 0.05)
    prob[:, 50] = 0.9
    prob[27:33, 50] = 0.05  # 0.3 m: the 0.4 m robot cannot pass
    assert GlobalPlanner(ExploreParams()).plan(_costmap(prob), (0.5, 0.5), (4.5, 0.5)) is None


def test_unknown_space_is_plannable_but_dearer_than_free():
    prob = np.full((40, 100), 0.05)
    prob[10:30, 20:80] = np.nan  # an unknown block in the middle of the straight line
    cm = _costmap(prob)
    p = ExploreParams()
    path = GlobalPlanner(p).plan(cm, (0.5, 1.0), (4.5, 1.0))
    assert path is not None  # around the block through known free space, not across it
    cells = np.floor(path / RES).astype(int)
    assert not cm.unknown[cells[:, 1], cells[:, 0]].any()
    prob[0:10, 20:80] = 0.9
    prob[30:, 20:80] = 0.9
    path = GlobalPlanner(p).plan(_costmap(prob), (0.5, 1.0), (4.5, 1.0))
    assert path is not None  # the only way is through the unknown block
    blocked = GlobalPlanner(ExploreParams(allow_unknown=False)).plan(
        _costmap(prob), (0.5, 1.0), (4.5, 1.0)
    )
    assert blocked is None


def test_start_inside_inscribed_zone_can_escape():
    prob = np.full((40, 40), 0.05)
    prob[:, 20] = 0.9
    cm = _costmap(prob)
    start = (21 * RES + 0.025, 1.0)  # 0.05 m from the wall: cost 253
    assert cm.inflated[20, 21] == 253
    path = GlobalPlanner(ExploreParams()).plan(cm, start, (1.8, 1.0))
    assert path is not None and path[-1][0] > 1.7


def test_a_star_plan_costs_the_same_as_dijkstra():
    rng = np.random.default_rng(5)
    prob = np.where(rng.random((80, 80)) < 0.04, 0.9, 0.05)
    prob[rng.random((80, 80)) < 0.1] = np.nan
    cm = _costmap(prob)
    p = ExploreParams()
    free = np.argwhere((cm.inflated < 253) & ~cm.unknown)
    for k in range(5):
        (sy, sx), (gy, gx) = free[rng.integers(len(free), size=2)]
        target = np.zeros(cm.shape, dtype=bool)
        target[gy, gx] = True
        plain, star = DijkstraSearch(), DijkstraSearch()
        a = plain.run(cm, (sx, sy), target, p)
        b = star.run(cm, (sx, sy), target, p, goal_cell=(gx, gy))
        assert len(a) == len(b)
        if len(a):
            assert math.isclose(plain.potential[gy, gx], star.potential[gy, gx], rel_tol=1e-9)
            # A* settles fewer cells
            assert (star.stamp == star.run_id).sum() <= (plain.stamp == plain.run_id).sum()
        _ = k
