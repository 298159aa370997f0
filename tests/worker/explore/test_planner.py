"""navfn-like planner: Dijkstra potentials, paths through gaps, unreachable goals, escaping."""

from __future__ import annotations

import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra as sp_dijkstra

from worker.explore.costmap import GlobalCostmap
from worker.explore.flat_params import explore_params
from worker.explore.params import ExploreParams
from worker.explore.planner import DijkstraSearch, GlobalPlanner, path_length, planner_blocked_cost

RES = 0.05


def _costmap(prob):
    cm = GlobalCostmap(ExploreParams().costmap)
    cm.update(prob.astype(np.float32), RES, (0.0, 0.0))
    return cm


def test_potential_on_open_ground_is_octile_distance_times_neutral_cost():
    cm = _costmap(np.full((41, 41), 0.05))
    target = np.zeros(cm.shape, dtype=bool)
    target[30, 35] = True
    search = DijkstraSearch()
    found = search.run(cm, (5, 10), target, ExploreParams().planner)
    assert len(found) == 1 and found[0] == 30 * 41 + 35
    dx, dy = 30, 20  # 20 diagonal steps and 10 straight ones
    assert math.isclose(search.potential[30, 35], 50.0 * (10 + 20 * math.sqrt(2)), rel_tol=1e-12)
    assert math.isclose(search.potential_at(found)[0], 50.0 * (dx - dy + dy * math.sqrt(2)))


def test_path_goes_through_the_door_and_keeps_off_walls():
    prob = np.full((60, 100), 0.05)
    prob[:, 50] = 0.9
    prob[24:36, 50] = 0.05  # a 0.6 m door in the wall, cells 24..35
    cm = _costmap(prob)
    path = GlobalPlanner(ExploreParams().planner).plan(cm, (0.5, 0.5), (4.5, 0.5))
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
    assert GlobalPlanner(ExploreParams().planner).plan(cm, (0.5, 0.5), (4.5, 0.5)) is None


def test_door_narrower_than_the_robot_is_refused():
    prob = np.full((60, 100), 0.05)
    prob[:, 50] = 0.9
    prob[27:33, 50] = 0.05  # 0.3 m: the 0.4 m robot cannot pass
    assert (
        GlobalPlanner(ExploreParams().planner).plan(_costmap(prob), (0.5, 0.5), (4.5, 0.5)) is None
    )


def test_unknown_space_is_plannable_but_dearer_than_free():
    prob = np.full((40, 100), 0.05)
    prob[10:30, 20:80] = np.nan  # an unknown block in the middle of the straight line
    cm = _costmap(prob)
    p = ExploreParams()
    path = GlobalPlanner(p.planner).plan(cm, (0.5, 1.0), (4.5, 1.0))
    assert path is not None  # around the block through known free space, not across it
    cells = np.floor(path / RES).astype(int)
    assert not cm.unknown[cells[:, 1], cells[:, 0]].any()
    prob[0:10, 20:80] = 0.9
    prob[30:, 20:80] = 0.9
    path = GlobalPlanner(p.planner).plan(_costmap(prob), (0.5, 1.0), (4.5, 1.0))
    assert path is not None  # the only way is through the unknown block
    blocked = GlobalPlanner(explore_params(allow_unknown=False).planner).plan(
        _costmap(prob), (0.5, 1.0), (4.5, 1.0)
    )
    assert blocked is None


def test_start_inside_inscribed_zone_can_escape():
    prob = np.full((40, 40), 0.05)
    prob[:, 20] = 0.9
    cm = _costmap(prob)
    start = (21 * RES + 0.025, 1.0)  # 0.05 m from the wall: cost 253
    assert cm.inflated[20, 21] == 253
    path = GlobalPlanner(ExploreParams().planner).plan(cm, start, (1.8, 1.0))
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
        a = plain.run(cm, (sx, sy), target, p.planner)
        b = star.run(cm, (sx, sy), target, p.planner, goal_cell=(gx, gy))
        assert len(a) == len(b)
        if len(a):
            assert math.isclose(plain.potential[gy, gx], star.potential[gy, gx], rel_tol=1e-9)
            # A* settles fewer cells
            assert (star.stamp == star.run_id).sum() <= (plain.stamp == plain.run_id).sum()
        _ = k


def _walled_in_goal():
    prob = np.full((200, 200), 0.05)
    prob[150:180, 150] = prob[150:180, 179] = 0.9  # a closed 30 x 30-cell room, far corner
    prob[150, 150:180] = prob[179, 150:180] = 0.9
    return _costmap(prob)


def test_a_walled_in_goal_is_proved_unreachable_on_its_side():
    cm, p = _walled_in_goal(), ExploreParams()
    search = DijkstraSearch()
    target = np.zeros(cm.shape, dtype=bool)
    target[165, 165] = True
    assert search.run(cm, (10, 10), target, p.planner, goal_cell=(165, 165)).size == 0
    everything = (search.stamp == search.run_id).sum()  # the search covered all it reached
    assert search.sealed_off(cm, (10, 10), (165, 165), p.planner)
    flooded = (search.stamp == search.run_id).sum()
    assert flooded < 28 * 28 < everything / 40  # only the room's inside was looked at
    assert GlobalPlanner(p.planner).plan(cm, (0.5, 0.5), (165 * RES, 165 * RES)) is None
    # outside the room, or with the start inside it: no proof, and the search finds it
    assert not search.sealed_off(cm, (10, 10), (120, 120), p.planner)
    assert not search.sealed_off(cm, (160, 160), (165, 165), p.planner)
    assert GlobalPlanner(p.planner).plan(cm, (0.5, 0.5), (6.0, 6.0)) is not None


def test_sealed_off_never_contradicts_the_search():
    rng = np.random.default_rng(11)
    prob = np.full((120, 120), 0.05)
    for _ in range(40):  # wall segments that close off pockets here and there
        y, x, n = rng.integers(0, 120), rng.integers(0, 120), rng.integers(5, 40)
        if rng.random() < 0.5:
            prob[y, x : x + n] = 0.9
        else:
            prob[y : y + n, x] = 0.9
    prob[rng.random((120, 120)) < 0.05] = np.nan
    cm, p = _costmap(prob), ExploreParams()
    proofs = 0
    for _ in range(300):
        (sy, sx), (gy, gx) = rng.integers(0, 120, size=(2, 2))
        target = np.zeros(cm.shape, dtype=bool)
        target[gy, gx] = True
        for escape in (None, p.planner.pocket_escape_radius):
            search = DijkstraSearch()
            found = search.run(cm, (sx, sy), target, p.planner, goal_cell=(gx, gy), escape_m=escape)
            if search.sealed_off(cm, (sx, sy), (gx, gy), p.planner, escape_m=escape):
                proofs += 1
                assert found.size == 0, ((sx, sy), (gx, gy), escape)
    assert proofs > 20  # the proof is exercised, not only its refusals


def test_pocket_escape_crosses_no_inscribed_gap_beyond_the_escape_radius():
    # a wall at x = 3 m with two openings: a 0.2 m slit 1 m from the robot (its cells are
    # inscribed: the 0.4 m robot does not fit) and a 0.5 m door 4 m up (under the 0.1 m
    # margin, above the inscribed radius: the squeeze pass's). The wide escape from a
    # pocket (1.5 m) once chained through the slit's inscribed cells; the plan must take
    # the door, and no inscribed cell beyond escape_radius.
    prob = np.full((120, 120), 0.05)
    prob[:, 60] = 0.9
    prob[18:22, 60] = 0.05  # the slit, y 0.9-1.1 m
    prob[95:105, 60] = 0.05  # the door, y 4.75-5.25 m
    cm = _costmap(prob)
    assert cm.inflated[19:21, 60].min() >= 253
    p = ExploreParams()
    start, goal = (2.0, 1.0), (4.5, 1.0)
    path = GlobalPlanner(p.planner).plan(cm, start, goal, squeeze=True)
    assert path is not None
    ix = np.floor(path[:, 0] / RES).astype(int)
    iy = np.floor(path[:, 1] / RES).astype(int)
    far = np.hypot(path[:, 0] - start[0], path[:, 1] - start[1]) > p.planner.escape_radius
    assert cm.inflated[iy[far], ix[far]].max() < 253
    crossing = path[np.argmin(np.abs(path[:, 0] - 3.025))]
    assert 4.75 < crossing[1] < 5.25


def test_potentials_match_scipy_dijkstra_on_a_large_random_costmap():
    """Every cell's potential, the search run to its end (no target), against
    scipy.sparse.csgraph's Dijkstra on the same graph built independently: a step into a cell
    costs (neutral + factor * cost) times 1 or sqrt(2), unknown cells 253 times that. The map
    is large enough that the search's heap outgrows its first 4,096 entries."""
    rng = np.random.default_rng(11)
    n = 700
    prob = np.where(rng.random((n, n)) < 0.001, 0.9, rng.uniform(0.0, 0.2, (n, n)))
    prob[rng.random((n, n)) < 0.05] = np.nan
    cm = _costmap(prob)
    p = explore_params(allow_unknown=True)
    sy, sx = n // 2, n // 2
    cm.inflated[sy - 2 : sy + 3, sx - 2 : sx + 3] = 0  # no escaping at the start
    cm.unknown[sy - 2 : sy + 3, sx - 2 : sx + 3] = False
    search = DijkstraSearch()
    found = search.run(cm, (sx, sy), np.zeros(cm.shape, dtype=bool), p.planner, escape_m=0.0)
    assert len(found) == 0

    blocked = planner_blocked_cost(p.planner, p.costmap)
    c = cm.inflated.astype(float)
    enter = np.where(cm.unknown, 253.0, p.planner.neutral_cost + p.planner.cost_factor * c)
    enter[cm.inflated >= blocked] = np.inf  # lethal and inscribed (blocked <= 253) alike
    idx = np.arange(n * n).reshape(n, n)
    rows, cols, w = [], [], []
    for dy, dx in ((-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)):
        src = idx[max(0, -dy) : n - max(0, dy), max(0, -dx) : n - max(0, dx)]
        dst = idx[max(0, dy) : n - max(0, -dy), max(0, dx) : n - max(0, -dx)]
        cost = enter.reshape(-1)[dst.reshape(-1)] * math.hypot(dy, dx)
        ok = np.isfinite(cost)
        rows.append(src.reshape(-1)[ok])
        cols.append(dst.reshape(-1)[ok])
        w.append(cost[ok])
    graph = coo_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n * n, n * n)).tocsr()  # fmt: skip
    ref = sp_dijkstra(graph, directed=True, indices=sy * n + sx).reshape(n, n)
    settled = search.stamp == search.run_id
    assert np.array_equal(settled, np.isfinite(ref))
    assert settled.sum() > 100_000
    np.testing.assert_allclose(search.potential[settled], ref[settled], rtol=1e-9)
    # paths traced back from the 1-byte step codes: 8-connected chains from the start whose
    # step costs sum to the cell's shortest distance (scipy's), so each is a shortest path
    for flat in rng.choice(np.flatnonzero(settled), 200, replace=False):
        path = search.path_to(int(flat))
        assert tuple(path[0]) == (sy, sx) and path[-1, 0] * n + path[-1, 1] == flat
        steps = np.diff(path, axis=0)
        assert np.all(np.abs(steps).max(axis=1) == 1)
        cost = enter[path[1:, 0], path[1:, 1]] * np.hypot(steps[:, 0], steps[:, 1])
        np.testing.assert_allclose(cost.sum(), ref.reshape(-1)[flat], rtol=1e-9)
