"""Incremental map assembly: the same map as assembling every patch, and `map_changes` tells a
consumer exactly where to refresh its copy."""

from __future__ import annotations

import numpy as np
import pytest

from worker.slam.assembly import dense_prob
from worker.slam.params import SlamParams
from worker.slam.patchmap import PATCH, PatchMaps
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

ROOM = (0.0, 0.0, 14.0, 9.0)


def _beam(maps, pose, r):
    maps.register(np.atleast_2d(pose), np.array([r]), np.ones(1), np.zeros(1), 30.0, 29.99)


def _whole(maps: PatchMaps, particle: int):
    """(prob, origin) of one particle's map assembled whole, cropped with numpy (the former
    PatchMaps.occupancy): the reference."""
    prob = dense_prob(maps.visits, maps.hslot, maps.hits, maps.tables[particle])
    known = ~np.isnan(prob)
    rows, cols = np.flatnonzero(known.any(axis=1)), np.flatnonzero(known.any(axis=0))
    side = maps.resolution * PATCH
    origin = np.array([maps.tpx0 * side + cols[0] * maps.resolution,
                       maps.tpy0 * side + rows[0] * maps.resolution])  # fmt: skip
    return prob[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1], origin


def _wander(n: int, seed: int):
    """n scans of a robot wandering in ROOM (odometry with a 5 % stride error): t, odom, scans."""
    rng = np.random.default_rng(seed)
    laser = Laser()
    pose = np.array([2.0, 2.0, 0.3])
    poses, odom = [], [pose.copy()]
    for _ in range(n):
        pose = pose + np.array([0.12 * np.cos(pose[2]), 0.12 * np.sin(pose[2]), 0.0])
        pose[2] += rng.normal(0.0, 0.25)
        pose[:2] = np.clip(pose[:2], [1.0, 1.0], [13.0, 8.0])
        poses.append(pose.copy())
    for a, b in zip(poses[:-1], poses[1:], strict=True):
        odom.append(odom[-1] + (b - a) * np.array([1.05, 1.05, 1.0]))
    scans = np.array([box_scan(p, laser.angles, ROOM) for p in poses])
    return laser, 0.1 * np.arange(n), np.array(odom[:n]), scans


@pytest.mark.parametrize("threads", [1, 2])
def test_incremental_map_is_the_whole_assembly_after_every_update(threads):
    # resampling re-points rows of the table and the best particle changes: both must be seen
    laser, t, odom, scans = _wander(160, seed=3)
    params = SlamParams(particles=6, linear_update=0.3, angular_update=0.2, threads=threads)
    slam = make_slam("rbpf", laser, params, np.random.default_rng(2))
    checked = 0
    for k in range(len(t)):
        if not slam.process(t[k], odom[k], scans[k]):
            continue
        best = int(np.argmax(slam.log_weight_sums))
        grid = slam.occupancy()
        prob, origin = _whole(slam.maps, best)
        assert grid.prob.tobytes() == prob.tobytes()
        assert np.array_equal(grid.origin, origin)
        checked += 1
    assert checked > 20 and slam.resamplings > 0


def test_map_changes_of_single_beams():
    maps = PatchMaps(1, 0.1, 2.0, 0.25)
    side = 0.1 * PATCH  # 3.2 m patches
    assert maps.changes(0).shape == (0, 4)
    _beam(maps, [0.05, 0.05, 0.0], 1.03)  # cells 0-10 of row 0: patch (0, 0)
    assert np.allclose(maps.changes(0), [[0.0, 0.0, side, side]])
    assert maps.changes(0).shape == (0, 4)  # nothing since
    # the same beam again: more visits and hits, but every hits / visits ratio is the same
    _beam(maps, [0.05, 0.05, 0.0], 1.03)
    assert maps.changes(0).shape == (0, 4)
    # from x = 10.05 m: cells 100-110, patch column 3 (cells 96-127), past the table: it grows
    _beam(maps, [10.05, 0.05, 0.0], 1.03)
    assert np.allclose(maps.changes(0), [[3 * side, 0.0, 4 * side, side]])
    # from the first pose, 11.03 m: cells 0-109 get a visit, 110 a hit. Cells 0-9 stay 0 and
    # 100-110 keep their ratios (0, and 2 hits in 2 visits), but cell 10 drops to 2 / 3 and
    # cells 11-99 are seen for the first time: patch columns 0-3, one run on the row
    _beam(maps, [0.05, 0.05, 0.0], 11.03)
    assert np.allclose(maps.changes(0), [[0.0, 0.0, 4 * side, side]])
    # two beams one patch row apart: the same column run on rows 1 and 2 merges into one
    # rectangle (y from 3.25 m and 6.45 m: patch rows 1 and 2, cells 0-10: column 0)
    _beam(maps, [0.05, 3.25, 0.0], 1.03)
    _beam(maps, [0.05, 6.45, 0.0], 1.03)
    assert np.allclose(maps.changes(0), [[0.0, side, side, 3 * side]])


def test_a_copy_refreshed_where_map_changes_says_matches_the_map():
    laser, t, odom, scans = _wander(120, seed=4)
    params = SlamParams(particles=5, linear_update=0.3, angular_update=0.2)
    slam = make_slam("rbpf", laser, params, np.random.default_rng(1))
    res, extent = params.delta, 40.0  # a fixed canvas of 40 m x 40 m around the start
    lo = odom[0, :2] - extent / 2
    canvas = np.full((int(extent / res),) * 2, np.nan, np.float32)

    def paste(grid, rect=None):
        """Write grid's cells (those inside rect [x0, y0, x1, y1], or all) onto a NaN canvas
        region; returns the region's slices."""
        out = np.full_like(canvas, np.nan)
        c0, r0 = np.round((grid.origin - lo) / res).astype(int)
        h, w = grid.shape
        out[r0 : r0 + h, c0 : c0 + w] = grid.prob
        if rect is None:
            return out
        x0, y0, x1, y1 = np.round((np.asarray(rect) - np.tile(lo, 2)) / res).astype(int)
        return (slice(y0, y1), slice(x0, x1)), out

    updates = 0
    for k in range(len(t)):
        if not slam.process(t[k], odom[k], scans[k]):
            continue
        updates += 1
        rects = slam.map_changes()
        grid = slam.occupancy()
        for rect in rects:
            region, fresh = paste(grid, rect)
            canvas[region] = fresh[region]
        assert paste(grid).tobytes() == canvas.tobytes()
    assert updates > 15
