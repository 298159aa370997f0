"""The door passage (door.DoorPass) and the map-only layers it drives on."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from worker.explore import costmap_kernels as ck
from worker.explore.costmap import GlobalCostmap
from worker.explore.door import DoorPass, _ahead, find_passage
from worker.explore.params import ExploreParams

RES = 0.05
WALL_X = 60  # the wall's cells: x in [3.0, 3.1) m (two cells thick)


def _door_map(door_cells: int) -> np.ndarray:
    """(80, 120) SLAM probabilities: free, a wall two cells thick at x = 3.0 m with a door
    of `door_cells` free cells centred on y = 2.0 m."""
    prob = np.full((80, 120), 0.02, dtype=np.float32)
    prob[:, WALL_X : WALL_X + 2] = 0.9
    prob[40 - door_cells // 2 : 40 - door_cells // 2 + door_cells, WALL_X : WALL_X + 2] = 0.02
    return prob


def _params(**kw) -> ExploreParams:
    return dataclasses.replace(ExploreParams(), door_align=True, **kw)


def _find(path, x, y, local, p):
    """find_passage on the path ahead of (x, y)."""
    return find_passage(*_ahead(path, x, y, p), local, p)


def _drive_through(p: ExploreParams, cm: GlobalCostmap, pose, path, steps: int = 300):
    """Unicycle integration of DoorPass's commands at 10 Hz; the poses and the kinds."""
    door = DoorPass(p)
    poses, kinds = [np.array(pose, dtype=float)], []
    x, y, th = pose
    for _ in range(steps):
        cmd = door.command(np.array([x, y, th]), path, cm)
        if cmd is None:
            break
        v, w, kind = cmd
        kinds.append(kind)
        for _ in range(10):  # 0.1 s in ten sub-steps
            x += v * math.cos(th) * 0.01
            y += v * math.sin(th) * 0.01
            th += w * 0.01
        poses.append(np.array([x, y, th]))
    return np.array(poses), kinds, door


def _footprint_hits_wall(cm: GlobalCostmap, x: float, y: float, th: float, half: float) -> bool:
    """Whether the exact square footprint covers a map obstacle cell (sampled densely)."""
    c, s = math.cos(th), math.sin(th)
    for u in np.linspace(-half, half, 17):
        for v in np.linspace(-half, half, 17):
            px, py = x + u * c - v * s, y + u * s + v * c
            ix, iy = int(math.floor(px / RES)), int(math.floor(py / RES))
            if cm.map_lethal[iy, ix]:
                return True
    return False


def test_map_lethal_is_the_map_alone_and_only_kept_for_the_door_passage():
    prob = _door_map(10)
    cm = GlobalCostmap(_params(obstacle_min_prob=0.0))  # every mark counts
    cm.update(prob, RES, (0.0, 0.0), scan=(np.array([2.0, 2.0, 0.0]), np.array([0.6]),
                                           np.array([0.0]), 30.0))  # fmt: skip
    assert np.array_equal(cm.map_lethal, prob > 0.25)
    assert cm.lethal[40, 52] and not cm.map_lethal[40, 52]  # the obstacle layer's mark
    off = GlobalCostmap(dataclasses.replace(ExploreParams(), door_align=False))
    off.update(prob, RES, (0.0, 0.0))
    assert off.map_lethal.size == 0


def test_obstacle_marks_in_cells_the_map_knows_free_can_be_left_out():
    # a noisy short reading marks a cell the map has seen free many times (0.02), another
    # marks a wall face the map shows under occupied_thresh (0.2): with obstacle_min_prob
    # 0.1 only the second is an obstacle, with 0 (the default) both are
    prob = _door_map(10)
    prob[10, 50] = 0.2
    scans = [
        (np.array([2.0, 2.02, 0.0]), np.array([0.62])),  # ends in cell (40, 52): p 0.02
        (np.array([2.0, 0.52, 0.0]), np.array([0.52])),  # ends in cell (10, 50): p 0.2
    ]
    for min_prob, expected in ((0.0, [True, True]), (0.1, [False, True])):
        cm = GlobalCostmap(dataclasses.replace(ExploreParams(), obstacle_min_prob=min_prob))
        for pose, r in scans:
            cm.update(prob, RES, (0.0, 0.0), scan=(pose, r, np.array([0.0]), 30.0))
        assert [bool(cm.lethal[40, 52]), bool(cm.lethal[10, 50])] == expected


def test_a_passage_is_found_where_both_sides_are_near_and_not_in_a_corridor():
    p = _params()
    cm = GlobalCostmap(p)
    cm.update(_door_map(10), RES, (0.0, 0.0))
    path = np.column_stack((np.arange(1.5, 4.5, RES), np.full(60, 2.025)))
    from worker.explore.costmap import LocalCostmap

    local = LocalCostmap(p, RES)
    local.build(2.4, 2.0, cm, 0.0, map_only=True)
    entry, exit_ = _find(path, 2.4, 2.0, local, p)[:2]
    assert 2.7 <= entry[0] <= 3.01 and 3.1 <= exit_[0] <= 3.5  # through the wall's cells
    local.build(1.5, 2.0, cm, 0.0, map_only=True)
    assert _find(path, 1.5, 2.0, local, p) is None  # farther than door_lookahead
    wide = GlobalCostmap(p)
    wide.update(_door_map(24), RES, (0.0, 0.0))  # 1.2 m: wider than door_width
    local.build(2.4, 2.0, wide, 0.0, map_only=True)
    assert _find(path, 2.4, 2.0, local, p) is None


def test_the_robot_lines_up_with_a_tight_door_and_drives_through_without_touching():
    # a 0.5 m door (10 cells) for the 0.4 m robot: it comes 0.12 m off the door's axis at
    # 1 rad to it, as it came off a diagonal plan, and must not touch the jambs
    p = _params()
    cm = GlobalCostmap(p)
    cm.update(_door_map(10), RES, (0.0, 0.0))
    path = np.column_stack((np.arange(2.0, 4.5, RES), np.full(50, 2.0)))
    poses, kinds, door = _drive_through(p, cm, (2.2, 1.88, 1.0), path)
    assert poses[-1, 0] > 3.3 and door.n_passages == 1, "not through the door"
    assert not any(_footprint_hits_wall(cm, *q, p.footprint_half_m) for q in poses)
    in_door = poses[(poses[:, 0] > 2.75) & (poses[:, 0] < 3.35)]
    assert len(in_door) > 0
    assert np.abs(in_door[:, 2]).max() < 0.12  # faced along the door while in it
    assert np.abs(in_door[:, 1] - 2.0).max() < 0.04  # and kept to its axis
    assert "door_turn" in kinds  # it turned on the spot to line up first


def test_a_door_narrower_than_the_robot_is_not_forced():
    p = _params()
    cm = GlobalCostmap(p)
    cm.update(_door_map(7), RES, (0.0, 0.0))  # 0.35 m: narrower than the 0.4 m robot
    path = np.column_stack((np.arange(2.0, 4.5, RES), np.full(50, 2.0)))
    poses, kinds, _ = _drive_through(p, cm, (2.3, 2.0, 0.0), path)
    assert poses[-1, 0] < 3.0 - p.footprint_half_m + 0.02
    assert not any(_footprint_hits_wall(cm, *q, p.footprint_half_m) for q in poses)
    assert ck.LETHAL == 254  # the costmap values the checks rely on


def test_a_gap_between_pieces_of_furniture_is_not_a_door():
    # the same 0.5 m gap on the same path, once in a wall and once between two cabinets
    # 0.4 m long: only the first is a door (door_wall_min 1 m); the gap between the
    # cabinets is the DWA's, as every other gap between furniture
    from worker.explore.costmap import LocalCostmap

    p = _params()
    assert p.door_wall_min == 1.0
    path = np.column_stack((np.arange(1.5, 4.5, RES), np.full(60, 2.025)))
    furniture = np.full((80, 120), 0.02, dtype=np.float32)
    furniture[27:35, WALL_X : WALL_X + 2] = 0.9  # y in [1.35, 1.75): 0.4 m
    furniture[45:53, WALL_X : WALL_X + 2] = 0.9  # y in [2.25, 2.65)
    local = LocalCostmap(p, RES)
    for prob, is_door in ((_door_map(10), True), (furniture, False)):
        cm = GlobalCostmap(p)
        cm.update(prob, RES, (0.0, 0.0))
        local.build(2.4, 2.0, cm, 0.0, map_only=True)
        assert (_find(path, 2.4, 2.0, local, p) is not None) is is_door
    long_cabinets = furniture.copy()
    long_cabinets[15:35, WALL_X : WALL_X + 2] = 0.9  # 1.0 m long each: wall enough
    long_cabinets[45:65, WALL_X : WALL_X + 2] = 0.9
    cm = GlobalCostmap(p)
    cm.update(long_cabinets, RES, (0.0, 0.0))
    local.build(2.4, 2.0, cm, 0.0, map_only=True)
    assert _find(path, 2.4, 2.0, local, p) is not None


def test_a_door_it_gets_no_farther_into_is_given_up_to_the_dwa():
    # a 0.6 m door with a post the map holds 0.15 m past it, on the axis: the robot lines
    # up and drives in, but no motion takes it farther; after door_patience (10 s) the
    # passage is refused, and the same door is not taken up again
    p = _params()
    prob = _door_map(12)
    prob[38:42, WALL_X + 5 : WALL_X + 7] = 0.9  # x in [3.25, 3.35), y in [1.9, 2.1)
    cm = GlobalCostmap(p)
    cm.update(prob, RES, (0.0, 0.0))
    path = np.column_stack((np.arange(2.0, 4.5, RES), np.full(50, 2.0)))
    poses, kinds, door = _drive_through(p, cm, (2.3, 2.0, 0.0), path, steps=400)
    assert len(door.refused) == 1 and abs(door.refused[0][0] - 3.0) < 0.35
    n = len(kinds)
    assert p.door_patience * p.controller_frequency < n < 400  # it gave up, after patience
    assert not any(_footprint_hits_wall(cm, *q, p.footprint_half_m) for q in poses)
    assert door.command(poses[-1], path, cm) is None  # refused: left to the DWA


def test_the_passage_takes_over_only_where_the_dwa_sees_the_door_tight():
    # a 0.85 m door: as the map draws it the DWA drives through at speed, so the passage
    # leaves it alone; with a noisy scan's marks 0.2 m into the opening at both jambs (0.45
    # m left, under door_engage_width 0.8 m) the passage lines the robot up
    from worker.explore.costmap import LocalCostmap

    p = _params()
    cm = GlobalCostmap(p)
    cm.update(_door_map(17), RES, (0.0, 0.0))  # y in [1.6, 2.45)
    path = np.column_stack((np.arange(2.0, 4.5, RES), np.full(50, 2.025)))
    pose = np.array([2.4, 1.9, 0.8])
    clean = LocalCostmap(p, RES)
    clean.build(pose[0], pose[1], cm, pose[2])
    assert DoorPass(p).command(pose, path, cm, clean) is None
    noisy = LocalCostmap(p, RES)
    marks = np.array([[3.0 + dx, y] for dx in (0.0, 0.05) for y in (1.62, 1.72, 2.32, 2.42)])
    noisy.add_points(0.0, marks)
    noisy.build(pose[0], pose[1], cm, pose[2])
    cmd = DoorPass(p).command(pose, path, cm, noisy)
    assert cmd is not None and cmd[2] == "door_turn"  # facing 0.8 rad off the door's axis
    assert DoorPass(p).command(pose, path, cm) is not None  # no local costmap: every door
