"""Frontier search: frontier cells, clusters, min size, nearest by travel, blacklist, back-off."""

from __future__ import annotations

import numpy as np

from worker.explore.costmap import GlobalCostmap
from worker.explore.flat_params import explore_params
from worker.explore.frontiers import FrontierSearch
from worker.explore.navigator import Navigator
from worker.explore.params import ExploreParams
from worker.explore.planner import DijkstraSearch, GlobalPlanner, planner_blocked_cost

RES = 0.05


def _setup(prob, params=None):
    p = params or ExploreParams()
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(prob.astype(np.float32), RES, (0.0, 0.0))
    fs = FrontierSearch(p.frontiers, p.planner)
    fs.update(cm, None)
    return cm, fs


def test_frontier_cells_are_free_cells_touching_unknown():
    prob = np.full((20, 30), np.nan)
    prob[:, :10] = 0.05
    prob[5, 9] = 0.9  # an obstacle on the boundary is not a frontier
    cm, fs = _setup(prob)
    expected = np.zeros((20, 30), dtype=bool)
    expected[:, 9] = True
    expected[5, 9] = False
    np.testing.assert_array_equal(fs.frontier, expected)
    assert fs.n_frontier_cells == 19


def test_incremental_frontier_update_tracks_the_map():
    prob = np.full((20, 30), np.nan)
    prob[:, :10] = 0.05
    cm, fs = _setup(prob)
    prob[:, 10:15] = 0.05  # the robot saw 5 more columns
    changed = cm.update(prob.astype(np.float32), RES, (0.0, 0.0), window_m=(0.4, 0.0, 0.8, 1.0))
    fs.update(cm, changed)
    assert fs.frontier[:, 14].all() and not fs.frontier[:, 9].any()
    assert fs.n_frontier_cells == 20 == fs.frontier.sum()


def test_clusters_and_minimum_size():
    prob = np.full((60, 60), 0.9)
    prob[5:55, 5:55] = 0.05
    prob[20:40, 54:] = np.nan  # a 1.0 m opening to the unknown on the right
    prob[30:33, :6] = np.nan  # a 0.15 m gap on the left: too small (< 0.5 m)
    cm, fs = _setup(prob)
    cells, labels = fs.clusters()
    sizes = sorted(np.bincount(labels))
    # right: column 53 beside the opening (20) + the free cells above and below it in column 54;
    # left: column 6 beside the gap (3) + the free cells above and below it in column 5
    assert sizes == [5, 22]
    goal = fs.choose(cm, (1.0, 1.5), [])
    assert goal is not None and goal.n_clusters == 1
    assert goal.goal_xy[0] > 2.0  # the big opening on the right, although the gap is nearer
    assert abs(goal.cluster_size_m - 22 * RES) < 1e-9


def test_free_cells_inside_a_wall_face_are_no_frontier():
    # a room (free) and, 1 m right of the robot, a wall whose face a particle filter drew
    # with free cells between occupied ones: column 40 occupied, 41 free, 42 occupied every
    # other row, the wall's unseen inside (unknown) from column 43. The free cells of
    # columns 41 and 42 border that inside, but lie within the inscribed radius of the
    # occupied cells: no frontier worth a goal, so nothing is left to explore
    prob = np.full((60, 60), 0.9)
    prob[5:55, 5:40] = 0.05
    prob[5:55, 41] = 0.05
    prob[5:55, 42] = np.where(np.arange(5, 55) % 2 == 0, 0.9, 0.05)
    prob[5:55, 43:55] = np.nan
    cm, fs = _setup(prob)
    assert fs.frontier[5:55, 42].any()  # column 42's free cells are frontier cells
    assert fs.choose(cm, (1.0, 1.5), []) is None
    # the same wall with a 1 m gap in its face: the room beyond is a frontier again
    prob[20:40, 40:43] = 0.05
    cm, fs = _setup(prob)
    goal = fs.choose(cm, (1.0, 1.5), [])
    assert goal is not None and 25 * RES < goal.frontier_xy[1] < 35 * RES


def _corridor_world():
    # Known free U-shaped corridor; two openings into the unknown: A at the end of the lower
    # branch (Euclidean-near the robot but far by travel), B just beyond a thin wall.
    prob = np.full((80, 120), 0.9)
    prob[10:30, 10:110] = 0.05  # lower branch
    prob[50:70, 10:110] = 0.05  # upper branch
    prob[10:70, 90:110] = 0.05  # the bend joining them on the right
    prob[50:70, :10] = np.nan  # opening A at the upper branch's left end
    prob[10:30, 110:] = np.nan  # opening B at the lower branch's right end
    return prob


def test_nearest_frontier_by_travel_not_by_straight_line():
    cm, fs = _setup(_corridor_world())
    robot = (1.0, 1.0)  # lower branch, left end: A is 2.5 m away through the wall, B ~4.5 m
    goal = fs.choose(cm, robot, [])
    assert goal is not None and goal.goal_xy[0] > 4.5  # B, at the lower branch's right end
    a_goal = fs.choose(cm, (1.0, 3.0), [])  # in the upper branch now: A is nearest
    assert a_goal is not None and a_goal.goal_xy[0] < 1.5 and a_goal.goal_xy[1] > 2.4


def test_blacklisted_frontier_is_skipped_and_goal_faces_the_frontier():
    cm, fs = _setup(_corridor_world())
    first = fs.choose(cm, (1.0, 1.0), [])
    second = fs.choose(cm, (1.0, 1.0), [first.frontier_xy])
    assert second is not None and second.goal_xy[0] < 1.5  # opening A instead
    assert abs(abs(second.yaw) - np.pi) < 0.8  # A is to the goal's left (-x)
    assert abs(first.yaw) < 0.8  # B is to the goal's right (+x)
    none = fs.choose(cm, (1.0, 1.0), [first.frontier_xy, second.frontier_xy])
    assert none is None


def test_goal_is_backed_off_from_walls():
    cm, fs = _setup(_corridor_world())
    goal = fs.choose(cm, (1.0, 1.0), [])
    ix, iy = cm.world_to_cell(*goal.goal_xy)
    assert (
        np.hypot(*(goal.goal_xy - goal.frontier_xy)) <= ExploreParams().frontiers.goal_radius + 1e-9
    )
    # the lowest-cost candidate: on the even sub-lattice, among the cells near the opening
    # (x >= 4.9) none is cheaper; the corridor's edge cells (0.05 m from a wall) cost 253
    near = np.zeros(cm.shape, dtype=bool)
    near[0::2, 0::2] = True
    ys, xs = np.nonzero(near & (cm.inflated < 253) & ~cm.unknown)
    cx, cy = cm.cell_to_world(xs, ys)
    close = np.hypot(cx - goal.frontier_xy[0], cy - goal.frontier_xy[1]) <= 0.6
    assert cm.inflated[iy, ix] == cm.inflated[ys[close], xs[close]].min()
    assert cm.inflated[iy, ix] < 20


def test_unreachable_frontier_is_not_chosen():
    prob = np.full((60, 100), 0.9)
    prob[10:50, 5:45] = 0.05  # the robot's room, closed
    prob[10:50, 55:95] = 0.05  # another room seen through the wall, open to the unknown
    prob[20:40, 95:] = np.nan
    cm, fs = _setup(prob)
    assert fs.n_frontier_cells > 0
    assert fs.choose(cm, (1.0, 1.5), []) is None
    assert fs.frontier_near(cm, (4.8, 1.5), 0.3)
    assert not fs.frontier_near(cm, (1.0, 1.5), 0.3)


def test_unknown_enclosed_by_known_cells_is_no_frontier():
    # a room open to the unknown through a 1 m door on the right, with the inside of a
    # 0.3 m x 0.3 m table leg (9 unknown cells in a ring of obstacle cells whose ring has a
    # gap, as a scan often leaves one) and of a 0.2 m x 1.5 m wall pillar unseen
    prob = np.full((60, 80), 0.9)
    prob[5:55, 5:60] = 0.05
    prob[25:45, 60:] = np.nan  # the door into the unknown
    prob[10:15, 10:15] = 0.9
    prob[11:14, 11:14] = np.nan
    prob[12, 10] = 0.05  # the gap in the leg's ring: its free cell is a frontier cell
    prob[30:60, 30:34] = 0.9
    prob[30:54, 31:33] = np.nan
    prob[30, 31:33] = 0.05
    cm, fs = _setup(prob)
    cells, labels = fs.clusters()
    is_open = fs.open_cells(cm, cells)
    assert fs.frontier[12, 10] and fs.frontier[30, 31] and fs.frontier[30, 59]
    open_set = {tuple(c) for c in cells[is_open]}
    assert open_set == {(r, 59) for r in range(25, 45)}
    # the enclosed pillar region is 46 cells: with a smaller limit it counts as open
    p = explore_params(min_unknown_area=40 * RES**2)
    cm2, fs2 = _setup(prob, p)
    cells2, _ = fs2.clusters()
    is_open2 = fs2.open_cells(cm2, cells2)
    assert {tuple(c) for c in cells2[is_open2]} == open_set | {(30, 31), (30, 32)}
    goal = fs.choose(cm, (1.0, 1.0), [])
    assert goal is not None and goal.goal_xy[0] > 2.4  # the door, not the leg nearby


def _stamp_reference(cells, labels, valid, offsets, inflated, unknown, blocked):
    """Plain-Python goal candidate stamping: the rule stamp_targets implements."""
    h, w = inflated.shape
    owner, order, seen = {}, [], {}
    for (cy, cx), c, ok in zip(cells, labels, valid, strict=True):
        if not ok:
            continue
        seen[c] = seen.get(c, 0) + 1
        if (seen[c] - 1) % 3:
            continue
        for dy, dx in offsets:
            jy, jx = cy + dy, cx + dx
            if jy % 2 or jx % 2 or not (0 <= jy < h and 0 <= jx < w) or (jy, jx) in owner:
                continue
            if unknown[jy, jx] or inflated[jy, jx] >= blocked:
                continue
            owner[(jy, jx)] = c
            order.append((jy, jx))
    return order, owner


def test_goal_candidates_match_a_plain_implementation():
    from worker.explore import frontier_kernels as fk
    from worker.explore.planner import cells_in_radius

    rng = np.random.default_rng(7)
    prob = np.full((70, 90), 0.05)
    for _ in range(12):  # unknown blocks and a few obstacle cells in a known free room
        y, x = rng.integers(0, 60), rng.integers(0, 80)
        prob[y : y + rng.integers(3, 10), x : x + rng.integers(3, 10)] = np.nan
    prob[rng.random((70, 90)) < 0.002] = 0.9
    cm, fs = _setup(prob)
    cells, labels = fs.clusters()
    np.testing.assert_array_equal(cells, np.argwhere(fs.frontier))
    valid = rng.random(len(cells)) < 0.8
    offsets = cells_in_radius(0.3, RES)
    marked = fk.stamp_targets(
        cells, labels, valid, offsets, cm.inflated, cm.unknown, fs._target, fs._owner, 120
    )
    order, owner = _stamp_reference(cells, labels, valid, offsets, cm.inflated, cm.unknown, 120)
    assert [tuple(m) for m in marked] == order and len(order) > 50
    assert all(fs._owner[y, x] == owner[(y, x)] for y, x in order)
    assert fs._target.sum() == len(order)


def test_frontier_looked_at_from_close_by_repeatedly_is_dead():
    # a closed room with a 0.6 m hole in its right wall's face; behind it, a 2.5 m x 0.5 m
    # unknown slab (the wall's unseen inside, too big for the enclosed-unknown rule)
    prob = np.full((60, 80), 0.9)
    prob[5:55, 5:60] = 0.05
    prob[5:55, 61:71] = np.nan
    prob[25:37, 60] = np.nan  # the hole in the face
    cm, fs = _setup(prob)
    assert fs.frontier[25:37, 59].all()
    assert fs.choose(cm, (2.0, 1.5), []) is not None
    p = ExploreParams()
    behind = np.array([2.5, 1.525, np.pi])  # 0.5 m away but facing away: out of view
    for _ in range(2 * p.frontiers.dead_frontier_looks):
        fs.observe(cm, behind, np.radians(135.0) - 0.05)
    assert not fs.seen.any()
    far = np.array([1.0, 1.525, 0.0])  # in view, but 2 m away
    fs.observe(cm, far, np.radians(135.0) - 0.05)
    assert not fs.seen.any()
    near = np.array([2.5, 1.525, 0.0])  # 0.5 m away, facing it, clear line of sight
    for _ in range(p.frontiers.dead_frontier_looks):
        assert fs.choose(cm, near[:2], []) is not None
        fs.observe(cm, near, np.radians(135.0) - 0.05)
    assert (fs.seen[25:37, 59] == p.frontiers.dead_frontier_looks).all()
    assert fs.choose(cm, near[:2], []) is None  # its only frontier is dead


def _room_behind_a_narrow_door():
    # the robot's room (x 0.25-2.5 m), a 0.25 m wall with a 0.3 m door (y 1.35-1.65), and
    # beyond it a room known 0.75 m deep, then unknown to the grid's edge: no centre of the
    # 0.4 m robot fits through the door, and every cell within goal_radius of the frontier
    # lies beyond it
    prob = np.full((60, 100), 0.9)
    prob[5:55, 5:50] = 0.05
    prob[27:33, 50:55] = 0.05  # the door
    prob[10:50, 55:70] = 0.05
    prob[10:50, 70:] = np.nan
    return prob


def test_a_frontier_behind_a_door_too_narrow_to_pass_is_looked_at_through_it():
    cm, fs = _setup(_room_behind_a_narrow_door())
    robot = (1.0, 1.5)
    assert fs.choose(cm, robot, []) is None  # no goal within goal_radius can be reached
    goal = fs.choose(cm, robot, [], look_through=True)
    assert goal is not None and goal.look_through
    p = ExploreParams()
    ys, xs = np.nonzero(fs.frontier)
    fx, fy = cm.cell_to_world(xs, ys)
    d = np.hypot(fx - goal.goal_xy[0], fy - goal.goal_xy[1])
    assert d.min() <= p.frontiers.look_through_radius + 1e-9
    # on the robot's side of the wall, in front of the door: the laser sees through it
    assert goal.goal_xy[0] < 2.5 and abs(goal.goal_xy[1] - 1.5) < 0.15
    # the nearest to the frontier of the cells a goal may take (below the planner's blocked
    # cost, on the even sub-lattice, on the robot's side): none is nearer than the goal
    ok = (cm.inflated < planner_blocked_cost(p.planner, p.costmap)) & ~cm.unknown
    ok[:, 50:] = False
    ok[1::2, :] = ok[:, 1::2] = False
    ys2, xs2 = np.nonzero(ok)
    wx, wy = cm.cell_to_world(xs2, ys2)
    nearest = np.hypot(fx[:, None] - wx, fy[:, None] - wy).min(axis=0)
    assert d.min() <= nearest.min() + 1e-9
    # the goals the robot reached there already (avoid) and the blacklist are respected
    other = fs.choose(cm, robot, [], [goal.goal_xy], look_through=True)
    assert (
        other is not None
        and np.hypot(*(other.goal_xy - goal.goal_xy)) > p.frontiers.blacklist_radius
    )
    assert fs.choose(cm, robot, [goal.frontier_xy], look_through=True) is None


def test_the_look_through_pass_is_off_at_radius_zero():
    p = explore_params(look_through_radius=0.0)
    nav = Navigator(p, np.linspace(-2.35, 2.35, 541), 30.0)
    nav.update_map(_room_behind_a_narrow_door().astype(np.float32), RES, (0.0, 0.0), True)
    cmd = nav.step(0.0, np.array([1.0, 1.5, 0.0]), 0.0, 0.0, np.full(541, 30.0))
    assert cmd.status == "no_frontier"
    nav = Navigator(ExploreParams(), np.linspace(-2.35, 2.35, 541), 30.0)
    nav.update_map(_room_behind_a_narrow_door().astype(np.float32), RES, (0.0, 0.0), True)
    cmd = nav.step(0.0, np.array([1.0, 1.5, 0.0]), 0.0, 0.0, np.full(541, 30.0))
    assert cmd.status != "no_frontier" and nav.goal.look_through


def test_no_look_through_at_unknown_space_smaller_than_a_room():
    # the same door, but the unknown beyond it is a closed 0.75 x 1.0 m pocket (0.75 m^2,
    # walled in: the unseen floor under a table is such a pocket): no viewpoint is worth it
    prob = _room_behind_a_narrow_door()
    prob[10:50, 85:] = 0.9
    prob[10:20, 70:85] = prob[40:50, 70:85] = 0.9
    cm, fs = _setup(prob)
    assert fs.choose(cm, (1.0, 1.5), [], look_through=True) is None
    # as a frontier for the ordinary search it is still open (over min_unknown_area)
    cells, _ = fs.clusters()
    assert fs.open_cells(cm, cells).any()
    cm, fs = _setup(prob, explore_params(look_through_min_area=0.7))
    assert fs.choose(cm, (1.0, 1.5), [], look_through=True) is not None


def test_goal_search_and_planner_sharing_buffers_give_what_separate_ones_give():
    """The navigator's frontier search and planner share one set of map-sized Dijkstra
    buffers (issue 21's memory): interleaved, each still gets the goal and plan it gets
    with buffers of its own."""
    p = ExploreParams()
    nav = Navigator(p, np.linspace(-np.pi / 2, np.pi / 2, 5), 10.0)
    assert nav.frontiers.search is nav.planner.search
    prob = _corridor_world()
    shared = DijkstraSearch()
    pairs = [
        (
            FrontierSearch(p.frontiers, p.planner, search=shared),
            GlobalPlanner(p.planner, search=shared),
        ),
        (FrontierSearch(p.frontiers, p.planner), GlobalPlanner(p.planner)),
    ]
    got = []
    for fs, planner in pairs:
        cm = GlobalCostmap(p.costmap, p.doors.door_align)
        cm.update(prob.astype(np.float32), RES, (0.0, 0.0))
        fs.update(cm, None)
        first = fs.choose(cm, (1.0, 1.0), [])
        path = planner.plan(cm, (1.0, 1.0), first.goal_xy)  # overwrites a shared search
        # the goal's own path, read back after the planner searched the same buffers
        second = fs.choose(cm, (1.0, 3.0), [first.frontier_xy])
        back = planner.plan(cm, (1.0, 3.0), (1.0, 1.0))
        got.append((first, path, second, back))
    (f1, p1, s1, b1), (f2, p2, s2, b2) = got
    assert p1 is not None and b1 is not None and f1.path_xy.shape[0] > 10
    for a, b in ((f1, f2), (s1, s2)):
        np.testing.assert_array_equal(a.goal_xy, b.goal_xy)
        np.testing.assert_array_equal(a.path_xy, b.path_xy)
        assert a.travel_cost == b.travel_cost
    np.testing.assert_array_equal(p1, p2)
    np.testing.assert_array_equal(b1, b2)


def test_spent_frontier_cells_leave_the_rest_of_their_cluster_a_blacklist_drops_it_whole():
    # a 4 m x 3 m room open along its whole right side, x = 4 m, to unknown space: one
    # frontier cluster 3 m long (the hall a laser without a return cannot fill from one spot)
    prob = np.full((64, 120), np.nan)
    prob[2:62, 2:80] = 0.0  # free: x 0.1..4.0 m, y 0.1..3.1 m
    prob[0:2, 0:80] = prob[62:64, 0:80] = prob[:, 0:2] = 1.0  # walls below, above, left
    cm, fs = _setup(prob)
    robot = (1.0, 1.5)
    first = fs.choose(cm, robot, [])
    assert first is not None and abs(first.frontier_xy[0] - 4.0) < 0.1
    r = ExploreParams().frontiers.blacklist_radius
    # the cells near where the robot arrived in vain are spent: the next goal serves the same
    # frontier, farther along it than blacklist_radius
    second = fs.choose(cm, robot, [], spent=[first.frontier_xy])
    assert second is not None and abs(second.frontier_xy[0] - 4.0) < 0.1
    assert np.hypot(*(second.frontier_xy - first.frontier_xy)) > r
    # the same point blacklisted (a goal that failed) drops the whole cluster: nothing left
    assert fs.choose(cm, robot, [first.frontier_xy]) is None
    # spent points every 0.5 m along the whole frontier: no open cell left
    spent = [np.array([4.0, y]) for y in np.arange(0.0, 3.3, 0.5)]
    assert fs.choose(cm, robot, [], spent=spent) is None


def test_cells_within_the_radius_of_points_match_a_test_of_every_cell_against_every_point():
    from worker.explore.frontier_kernels import within_radius

    rng = np.random.default_rng(5)
    # cell centres of a 0.05 m grid far from the origin (as a big building's), in random
    # order, and points on cell centres: many cells exactly 0.5 m (10 cells) from a point
    iy, ix = np.divmod(rng.permutation(200 * 300), 300)
    xs, ys = 150.0 + (ix + 0.5) * RES, 80.0 + (iy + 0.5) * RES
    on_cells = [np.array([xs[k], ys[k]]) for k in rng.integers(0, len(xs), 12)]
    anywhere = [rng.uniform((150.0, 80.0), (165.0, 90.0)) for _ in range(12)]
    outside = [np.array([140.0, 85.0])]  # no cell within reach
    for points in (on_cells, anywhere, on_cells + anywhere + outside, outside, []):
        plain = np.zeros(len(xs), dtype=bool)
        for p in points:
            plain |= np.hypot(xs - p[0], ys - p[1]) <= 0.5
        assert np.array_equal(within_radius(xs, ys, points, 0.5), plain)
    got, (px, py) = within_radius(xs, ys, on_cells[:1], 0.5), on_cells[0]  # 10 cells off: in
    dx, dy = np.round((xs - px) / RES).astype(int), np.round((ys - py) / RES).astype(int)
    assert got[(dx == 10) & (dy == 0)].all() and not got[(dx == 11) & (dy == 0)].any()
