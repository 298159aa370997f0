"""The correlative matcher: branch-and-bound equals an exhaustive search, and a known offset
between two closed-form scans of a box room is found."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from tests.worker.slam.graph.worlds import box_points, to_map
from tests.worker.slam.helpers import Laser, box_scan
from worker.slam.graph.match_kernels import (
    branch_and_bound,
    max_pyramid,
    point_normals,
    scan_points,
)
from worker.slam.graph.matcher import (
    PointMap,
    angular_step,
    fuse_with_prior,
    icp_point_to_line,
    opposed_share,
)

LASER = Laser()
BOX = (0.0, 0.0, 8.0, 5.0)


def _points(pose):
    return box_points(pose, LASER, BOX)


def _normals_map(pose, pts):
    n = point_normals(pts, 0.3)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.column_stack([c * n[:, 0] - s * n[:, 1], s * n[:, 0] + c * n[:, 1]])


def test_known_offset_between_two_scans_is_found():
    a = np.array([3.0, 2.0, 0.3])
    b = np.array([3.13, 1.93, 0.35])  # the second scan's true pose
    grid_only = PointMap(to_map(a, _points(a)), 0.05, 0.1, 5)
    res = grid_only.match(_points(b), a, 0.25, 0.349, 0.1)  # prior: the first pose
    assert res.score > 0.8
    # the grid alone: within half a cell (5 cm) and a degree
    assert np.hypot(*(res.pose[:2] - b[:2])) < 0.025
    assert abs(res.pose[2] - b[2]) < 0.0175
    # with the point-to-line ICP on the map's points: within 2 mm and 0.03 degrees
    with_icp = PointMap(to_map(a, _points(a)), 0.05, 0.1, 5, None, _normals_map(a, _points(a)))
    res = with_icp.match(_points(b), a, 0.25, 0.349, 0.1)
    assert np.hypot(*(res.pose[:2] - b[:2])) < 0.002
    assert abs(res.pose[2] - b[2]) < 0.0005


def test_branch_and_bound_equals_exhaustive_search():
    rng = np.random.default_rng(5)
    a = np.array([3.0, 2.0, 0.0])
    map_pts = to_map(a, _points(a)) + rng.normal(0, 0.02, size=(1, 2))
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


def test_fusion_with_the_prior_is_the_information_weighted_mean():
    # hand-derived: x fixed by the match (1e4 against the prior's 1e2), y left free (0),
    # heading half and half; headings compared on the circle (3.1 and -3.1 are 0.083 apart)
    pose = np.array([1.0, 2.0, 3.1])
    prior = np.array([1.5, 2.4, -3.1])
    info = np.diag([1e4, 0.0, 1e2])
    prior_info = np.diag([1e2, 1e2, 1e2])
    fused = fuse_with_prior(pose, info, prior, prior_info)
    d_theta = 2 * np.pi - 6.2
    assert fused[0] == pytest.approx(1.0 + 0.5 * 1e2 / (1e4 + 1e2), abs=1e-12)
    assert fused[1] == pytest.approx(2.4, abs=1e-12)
    assert fused[2] == pytest.approx(3.1 + 0.5 * d_theta, abs=1e-12)


def test_in_a_corridor_the_walls_fix_the_offset_across_and_the_prior_the_way_along():
    # a 2 m wide corridor, its ends out of an 8 m laser's reach: the scan's walls say nothing
    # about how far along it the robot is (no information along x), everything across it
    corridor = (0.0, 0.0, 100.0, 2.0)
    a = np.array([50.0, 1.0, 0.0])
    b = np.array([50.3, 1.05, 0.01])  # the scan's true pose

    def pts(pose):
        ang = LASER.angles
        return scan_points(box_scan(pose, ang, corridor, 8.0), np.cos(ang), np.sin(ang), 7.9, 0.05)

    map_pts = to_map(a, pts(a))
    tree = cKDTree(map_pts)
    pose, info = icp_point_to_line(pts(b), b + [0.0, 0.02, 0.0], tree, _normals_map(a, pts(a)),
                                   0.15, (0.05, 0.02))  # fmt: skip
    assert pose[1] == pytest.approx(1.05, abs=0.002) and pose[2] == pytest.approx(0.01, abs=5e-4)
    assert info[0, 0] < 1e-6 * info[1, 1]
    # the odometry's prediction is 0.2 m short along the corridor and 5 cm off across it
    prior = np.array([50.1, 1.0, 0.0])
    odo_info = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.02**2])
    fused = fuse_with_prior(pose, info, prior, odo_info)
    assert fused[0] == pytest.approx(50.1, abs=0.002)  # along: the prior's
    assert fused[1] == pytest.approx(1.05, abs=0.003)  # across: the walls'
    assert fused[2] == pytest.approx(0.01, abs=5e-4)
    # and through PointMap.match, from the correlative search on
    pm = PointMap(map_pts, 0.05, 0.1, 5, None, _normals_map(a, pts(a)))
    res = pm.match(pts(b), prior, 0.25, 0.349, 0.1, prior_information=odo_info)
    assert res.pose[0] == pytest.approx(50.1, abs=0.005)
    assert res.pose[1] == pytest.approx(1.05, abs=0.003)


def _wall_face(x_sensor: float):
    """A wall along x = 0, y in [-1, 1], as a scan from a sensor at (x_sensor, 0) facing the
    wall sees it: points (robot frame) 2 m ahead and their normals turned toward the sensor."""
    y = np.linspace(-1.0, 1.0, 41)
    pts = np.column_stack([np.full_like(y, abs(x_sensor)), y])
    return pts, point_normals(pts, 0.3)


def test_a_scan_placed_on_a_walls_other_face_has_its_normals_opposed():
    # by hand: the map saw the wall's west face from (-2, 0) facing east, so its normals
    # point west (-1, 0). The same scan geometry from (2, 0) facing west (heading pi) lands
    # on the same cells, but its normals point east: every pair is opposed. From (-2, 0)
    # facing east (the face the map saw) none is
    pts, nrm = _wall_face(-2.0)
    assert nrm[:, 0] == pytest.approx(-1.0)  # toward the sensor, in the robot frame
    west = np.array([-2.0, 0.0, 0.0])
    map_pts, map_nrm = to_map(west, pts), nrm.copy()
    pm = PointMap(map_pts, 0.05, 0.1, 3, normals=map_nrm)
    share, pairs = opposed_share(pm, pts, nrm, west, 0.1)
    assert share == 0.0 and pairs == 41
    east = np.array([2.0, 0.0, np.pi])
    share, pairs = opposed_share(pm, pts, nrm, east, 0.1)
    assert share == 1.0 and pairs == 41
    # out of reach of every map point: no pairs, no evidence
    assert opposed_share(pm, pts, nrm, np.array([-2.0, 5.0, 0.0]), 0.1) == (0.0, 0)
