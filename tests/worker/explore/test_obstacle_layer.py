"""The global costmap's obstacle layer: raytrace clearing, marking within range, walls."""

from __future__ import annotations

import math

import numpy as np

from worker.explore import costmap_kernels as ck
from worker.explore.costmap import GlobalCostmap
from worker.explore.frontiers import FrontierSearch
from worker.explore.params import ExploreParams

RES = 0.05
ANGLES = np.array([0.0])


def _trace(obstacle, pose, r, range_max=30.0, obstacle_range=30.0, raytrace_range=30.0):
    return ck.raytrace_scan(
        obstacle, 0.0, 0.0, RES, *pose, np.array([r]), ANGLES, range_max, obstacle_range,
        raytrace_range,
    )  # fmt: skip


def test_a_hit_is_marked_in_the_cell_behind_the_wall_face():
    obstacle = np.zeros((20, 100), dtype=bool)
    # robot at x = 0.5 m looking along +x, wall face at x = 2.0 m: the cell [2.0, 2.05)
    box = _trace(obstacle, (0.5, 0.52, 0.0), 1.5)
    assert np.argwhere(obstacle).tolist() == [[10, 40]]
    assert box == (10, 11, 40, 41)


def test_a_ghost_is_cleared_by_the_next_beam_through_it_and_far_returns_are_not_marked():
    obstacle = np.zeros((20, 100), dtype=bool)
    _trace(obstacle, (0.5, 0.52, 0.0), 0.6)  # a noisy short reading: a ghost at x = 1.1 m
    assert obstacle[10, 22]
    _trace(obstacle, (0.5, 0.52, 0.0), 1.5)  # the next reading passes through it
    assert not obstacle[10, 22] and obstacle[10, 40]
    # out of obstacle_range: not marked, but still clears along the beam
    obstacle[:] = False
    obstacle[10, 30] = True
    _trace(obstacle, (0.5, 0.52, 0.0), 2.0, obstacle_range=1.0)
    assert not obstacle.any()
    # no return (range_max): neither marks nor clears
    obstacle[10, 30] = True
    _trace(obstacle, (0.5, 0.52, 0.0), 30.0)
    assert np.argwhere(obstacle).tolist() == [[10, 30]]


def test_a_wall_face_the_map_shows_free_becomes_lethal_and_no_frontier():
    # SLAM map: free up to x = 2.0 m, the wall face cell x = 40 free (p 0.2 < 0.25), behind
    # it unknown: a frontier along the wall. The laser hits the face: lethal, no frontier.
    prob = np.full((20, 100), np.nan, dtype=np.float32)
    prob[:, :41] = 0.05
    prob[:, 40] = 0.2
    p = ExploreParams()
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    fs = FrontierSearch(p.frontiers, p.planner)
    fs.update(cm, cm.update(prob, RES, (0.0, 0.0)))
    assert not cm.lethal[:, 40].any() and fs.frontier[5:15, 40].all()
    angles = np.linspace(-0.3, 0.3, 61)
    pose = np.array([0.5, 0.5, 0.0])
    ranges = (2.0 - 0.5) / np.cos(angles)
    changed = cm.update(prob, RES, (0.0, 0.0), (0.0, 0.0, 5.0, 1.0), (pose, ranges, angles, 30.0))
    fs.update(cm, changed)
    # the beams' end cells along the face, between y = 0.5 -/+ 1.5 tan(0.3) (0.04..0.96 m)
    hit_rows = np.flatnonzero(cm.lethal[:, 40])
    assert hit_rows.min() <= math.floor((0.5 - 1.5 * math.tan(0.3)) / RES) + 1
    assert hit_rows.max() >= math.floor((0.5 + 1.5 * math.tan(0.3)) / RES) - 1
    assert cm.inflated[10, 40] == ck.LETHAL
    assert not fs.frontier[5:15, 40].any()
