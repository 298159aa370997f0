"""The correlative matcher: branch-and-bound equals an exhaustive search, and a known offset
between two closed-form scans of a box room is found."""

from __future__ import annotations

import numpy as np

from tests.worker.slam.helpers import Laser, box_scan
from worker.slam.graph.match_kernels import (
    branch_and_bound,
    max_pyramid,
    point_normals,
    scan_points,
)
from worker.slam.graph.matcher import PointMap, angular_step

LASER = Laser()
BOX = (0.0, 0.0, 8.0, 5.0)


def _points(pose):
    a = LASER.angles
    return scan_points(box_scan(pose, a, BOX), np.cos(a), np.sin(a), 29.0, 0.05)


def _to_map(pose, pts):
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.column_stack([pose[0] + c * pts[:, 0] - s * pts[:, 1],
                            pose[1] + s * pts[:, 0] + c * pts[:, 1]])  # fmt: skip


def _normals_map(pose, pts):
    n = point_normals(pts, 0.3)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.column_stack([c * n[:, 0] - s * n[:, 1], s * n[:, 0] + c * n[:, 1]])


def test_known_offset_between_two_scans_is_found():
    a = np.array([3.0, 2.0, 0.3])
    b = np.array([3.13, 1.93, 0.35])  # the second scan's true pose
    grid_only = PointMap(_to_map(a, _points(a)), 0.05, 0.1, 5)
    res = grid_only.match(_points(b), a, 0.25, 0.349, 0.1)  # prior: the first pose
    assert res.score > 0.8
    # the grid alone: within half a cell (5 cm) and a degree
    assert np.hypot(*(res.pose[:2] - b[:2])) < 0.025
    assert abs(res.pose[2] - b[2]) < 0.0175
    # with the point-to-line ICP on the map's points: within 2 mm and 0.03 degrees
    with_icp = PointMap(_to_map(a, _points(a)), 0.05, 0.1, 5, None, _normals_map(a, _points(a)))
    res = with_icp.match(_points(b), a, 0.25, 0.349, 0.1)
    assert np.hypot(*(res.pose[:2] - b[:2])) < 0.002
    assert abs(res.pose[2] - b[2]) < 0.0005


def test_branch_and_bound_equals_exhaustive_search():
    rng = np.random.default_rng(5)
    a = np.array([3.0, 2.0, 0.0])
    map_pts = _to_map(a, _points(a)) + rng.normal(0, 0.02, size=(1, 2))
    pm = PointMap(map_pts, 0.05, 0.1, 4)
    scan = _points(np.array([2.9, 2.1, 0.04]))[::3]
    prior, window = a, 6
    angles = prior[2] + angular_step(scan, 0.05) * np.arange(-8, 9)
    ox, oy = pm.origin
    none = np.array([0.0, 1.0])
    got = branch_and_bound(
        pm.pyramid,
        ox,
        oy,
        0.05,
        scan,
        prior,
        window,
        angles,
        0.0,
        none,
        none,
        np.array([0.0, 0.0, -1.0]),
    )
    # exhaustive: every angle and cell offset, nearest-cell lookups of the level-0 grid
    best = (-1.0, 0.0, 0, 0)
    h, w = pm.grid.shape
    for th in angles:
        c, s = np.cos(th), np.sin(th)
        cx = np.floor((prior[0] + c * scan[:, 0] - s * scan[:, 1] - ox) / 0.05).astype(int)
        cy = np.floor((prior[1] + s * scan[:, 0] + c * scan[:, 1] - oy) / 0.05).astype(int)
        for dx in range(-window, window + 1):
            for dy in range(-window, window + 1):
                x, y = cx + dx, cy + dy
                ok = (x >= 0) & (x < w) & (y >= 0) & (y < h)
                score = pm.grid[y[ok], x[ok]].astype(np.float64).sum() / len(scan)
                if score > best[0] + 1e-9:
                    best = (score, th, dx, dy)
    assert abs(got[0] - best[0]) < 1e-5
    assert (got[1], got[2], got[3]) == (best[1], best[2], best[3])


def test_pyramid_levels_are_block_maxima():
    rng = np.random.default_rng(1)
    grid = rng.random((13, 17)).astype(np.float32)
    pyr = max_pyramid(grid, 3)
    for k in range(4):
        n = 1 << k
        for iy in range(13):
            for ix in range(17):
                assert pyr[k, iy, ix] == grid[iy : iy + n, ix : ix + n].max()
