"""Doors on the path (door_geometry.find_door) and the map-only layers the passage reads."""

from __future__ import annotations

import math

import numpy as np

from tests.worker.explore.door_scenes import (
    RES,
    WALL_X,
    door_map,
    door_params,
    door_pass,
    find_on_path,
)
from worker.explore import door_kernels as dok
from worker.explore.costmap import GlobalCostmap
from worker.explore.flat_params import explore_params


def test_map_lethal_is_the_map_alone_and_only_kept_for_the_door_passage():
    prob = door_map(10)
    cm = GlobalCostmap(door_params(obstacle_min_prob=0.0).costmap, True)  # every mark counts
    cm.update(prob, RES, (0.0, 0.0), scan=(np.array([2.0, 2.0, 0.0]), np.array([0.6]),
                                           np.array([0.0]), 30.0))  # fmt: skip
    assert np.array_equal(cm.map_lethal, prob > 0.25)
    assert cm.lethal[40, 52] and not cm.map_lethal[40, 52]  # the obstacle layer's mark
    off = GlobalCostmap(explore_params(door_align=False).costmap)
    off.update(prob, RES, (0.0, 0.0))
    assert off.map_lethal.size == 0


def test_obstacle_marks_in_cells_the_map_knows_free_can_be_left_out():
    # a noisy short reading marks a cell the map has seen free many times (0.02), another
    # marks a wall face the map shows under occupied_thresh (0.2): with obstacle_min_prob
    # 0.1 only the second is an obstacle, with 0 (the default) both are
    prob = door_map(10)
    prob[10, 50] = 0.2
    scans = [
        (np.array([2.0, 2.02, 0.0]), np.array([0.62])),  # ends in cell (40, 52): p 0.02
        (np.array([2.0, 0.52, 0.0]), np.array([0.52])),  # ends in cell (10, 50): p 0.2
    ]
    for min_prob, expected in ((0.0, [True, True]), (0.1, [False, True])):
        cm = GlobalCostmap(explore_params(obstacle_min_prob=min_prob).costmap)
        for pose, r in scans:
            cm.update(prob, RES, (0.0, 0.0), scan=(pose, r, np.array([0.0]), 30.0))
        assert [bool(cm.lethal[40, 52]), bool(cm.lethal[10, 50])] == expected


def test_a_passage_is_found_where_both_sides_are_near_and_not_in_a_corridor():
    p = door_params()
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(door_map(10), RES, (0.0, 0.0))
    path = np.column_stack((np.arange(1.5, 4.5, RES), np.full(60, 2.025)))
    from worker.explore.costmap import LocalCostmap

    local = LocalCostmap(p.costmap, p.dwa, RES)
    local.build(2.4, 2.0, cm, 0.0, map_only=True)
    door = find_on_path(path, 2.4, 2.0, local, p)
    # the jambs: the wall's cells nearest the door's middle, rows 45 (left of the path,
    # centre y 2.275 m) and 34 (right, 1.725 m); the centre between them, the axis along +x
    assert np.isclose(door.jambs[0][1], 2.275) and np.isclose(door.jambs[1][1], 1.725)
    assert abs(door.centre[1] - 2.0) < 1e-9 and 3.0 < door.centre[0] < 3.1
    assert np.allclose(door.axis, [1.0, 0.0])
    assert abs(door.width - 0.5) < 1e-9  # 10 free cells
    entry, exit_ = door.centre + door.s_in * door.axis, door.centre + door.s_out * door.axis
    assert 2.7 <= entry[0] <= 3.0 and 3.1 <= exit_[0] <= 3.5  # through the wall's cells
    local.build(1.5, 2.0, cm, 0.0, map_only=True)
    assert find_on_path(path, 1.5, 2.0, local, p) is None  # farther than door_lookahead
    wide = GlobalCostmap(p.costmap, p.doors.door_align)
    wide.update(door_map(24), RES, (0.0, 0.0))  # 1.2 m: wider than door_width
    local.build(2.4, 2.0, wide, 0.0, map_only=True)
    assert find_on_path(path, 2.4, 2.0, local, p) is None


def test_a_gap_between_pieces_of_furniture_is_not_a_door():
    # the same 0.5 m gap on the same path, once in a wall and once between two cabinets
    # 0.4 m long: only the first is a door (door_wall_min 1 m); the gap between the
    # cabinets is the DWA's, as every other gap between furniture
    from worker.explore.costmap import LocalCostmap

    p = door_params()
    assert p.doors.door_wall_min == 1.0
    path = np.column_stack((np.arange(1.5, 4.5, RES), np.full(60, 2.025)))
    furniture = np.full((80, 120), 0.02, dtype=np.float32)
    furniture[27:35, WALL_X : WALL_X + 2] = 0.9  # y in [1.35, 1.75): 0.4 m
    furniture[45:53, WALL_X : WALL_X + 2] = 0.9  # y in [2.25, 2.65)
    local = LocalCostmap(p.costmap, p.dwa, RES)
    for prob, is_door in ((door_map(10), True), (furniture, False)):
        cm = GlobalCostmap(p.costmap, p.doors.door_align)
        cm.update(prob, RES, (0.0, 0.0))
        local.build(2.4, 2.0, cm, 0.0, map_only=True)
        assert (find_on_path(path, 2.4, 2.0, local, p) is not None) is is_door
    long_cabinets = furniture.copy()
    long_cabinets[15:35, WALL_X : WALL_X + 2] = 0.9  # 1.0 m long each: wall enough
    long_cabinets[45:65, WALL_X : WALL_X + 2] = 0.9
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(long_cabinets, RES, (0.0, 0.0))
    local.build(2.4, 2.0, cm, 0.0, map_only=True)
    assert find_on_path(path, 2.4, 2.0, local, p) is not None


def test_a_wall_the_plan_turns_away_from_is_not_a_door():
    # the plan runs at a wall and turns along it 0.35 m before it: the wall is ahead of the
    # path, not across it, on either side
    from worker.explore.costmap import LocalCostmap

    p = door_params()
    prob = np.full((80, 120), 0.02, dtype=np.float32)
    prob[:, WALL_X : WALL_X + 2] = 0.9
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(prob, RES, (0.0, 0.0))
    leg1 = np.column_stack((np.arange(2.0, 2.65, RES), np.full(13, 2.0)))
    leg2 = np.column_stack((np.full(30, 2.65), 2.0 + RES * np.arange(1, 31)))
    path = np.vstack((leg1, leg2))
    local = LocalCostmap(p.costmap, p.dwa, RES)
    local.build(2.2, 2.0, cm, 0.0, map_only=True)
    assert find_on_path(path, 2.2, 2.0, local, p) is None
    assert door_pass(p).command(np.array([2.2, 2.0, 0.0]), path, cm) is None


def test_nearest_sides_splits_by_side_and_keeps_to_the_cone_across_the_line():
    # from (1.0, 1.0) along +x: a cell at (1.025, 1.325) is across on the left (0.325 m),
    # one at (1.025, 0.575) across on the right (0.425 m); a nearer one straight ahead at
    # (1.275, 1.025) is neither (0.28 m ahead, 0.025 m to the side); one at (1.475, 0.775)
    # is 0.475 m ahead and 0.225 m to the right: 64.6 degrees off the normal, inside a
    # 70 degree cone but not a 60 degree one
    lethal = np.zeros((40, 40), dtype=np.bool_)
    for x, y in ((1.025, 1.325), (1.025, 0.575), (1.275, 1.025), (1.475, 0.775)):
        lethal[int(y / RES), int(x / RES)] = True
    out = dok.nearest_sides(1.0, 1.0, 1.0, 0.0, lethal, 0.0, 0.0, RES, 0.9, dok.ACROSS_PATH)
    assert np.allclose(out, (1.025, 1.325, math.hypot(0.025, 0.325),
                             1.025, 0.575, math.hypot(0.025, 0.425)))  # fmt: skip
    wide = math.tan(math.radians(70.0))
    out = dok.nearest_sides(1.0, 1.0, 1.0, 0.0, lethal, 0.0, 0.0, RES, 0.9, wide)
    assert np.allclose(out[3:], (1.025, 0.575, math.hypot(0.025, 0.425)))  # 0.425 < 0.526
    lethal[int(0.575 / RES), int(1.025 / RES)] = False
    out = dok.nearest_sides(1.0, 1.0, 1.0, 0.0, lethal, 0.0, 0.0, RES, 0.9, wide)
    assert np.allclose(out[3:], (1.475, 0.775, math.hypot(0.475, 0.225)))
    out = dok.nearest_sides(1.0, 1.0, 1.0, 0.0, lethal, 0.0, 0.0, RES, 0.9, dok.ACROSS_PATH)
    assert out[5] == np.inf  # nothing across on the right any more
