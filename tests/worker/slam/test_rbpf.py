"""The particle filter on closed-form scans: corrects drifting odometry, shares maps, repeats."""

from __future__ import annotations

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.se2 import compose, relative
from worker.slam.base import SlamAlgorithm
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

BOX = (0.0, 0.0, 8.0, 5.0)


def _loop_log(laps: float = 1.0):
    """A rounded rectangle inside the room at 0.5 m/s, 10 Hz: t, pose_gt, pose_odom, scans.

    Odometry: 4 % too long a stride and a 0.04 rad/m heading drift (a systematic error
    much like Stage's, only larger), integrated from the true start pose.
    """
    laser = Laser()
    corners = np.array([[1.5, 1.5], [6.5, 1.5], [6.5, 3.5], [1.5, 3.5]])
    pts = []
    for k in range(4):
        a, b = corners[k], corners[(k + 1) % 4]
        n = int(np.hypot(*(b - a)) / 0.05)
        pts.append(a + (b - a) * np.arange(n)[:, None] / n)
    xy = np.concatenate(pts)
    xy = np.concatenate([xy] * int(np.ceil(laps)))[: int(len(xy) * laps)]
    heading = np.arctan2(*np.diff(xy, axis=0, append=xy[:1]).T[::-1])
    gt = np.column_stack([xy, heading])
    odom = [gt[0]]
    for k in range(1, len(gt)):
        d = relative(gt[k - 1], gt[k])
        step = np.hypot(d[0], d[1])
        d = d * np.array([1.04, 1.04, 1.0]) + np.array([0.0, 0.0, 0.04 * step])
        odom.append(compose(odom[-1], d))
    t = 0.1 * np.arange(len(gt))
    scans = np.array([box_scan(p, laser.angles, BOX) for p in gt])
    return laser, t, gt, np.array(odom), scans


def _run(slam: SlamAlgorithm, t, odom, scans):
    est = []
    for k in range(len(t)):
        slam.process(t[k], odom[k], scans[k])
        est.append(slam.pose_estimate())
    return np.array(est)


@pytest.mark.parametrize("coarse", [(0, 0), (1, 3)])
def test_rbpf_corrects_drifting_odometry_and_maps_the_room(coarse):
    # also with the coarse-to-fine climb (every second beam for the first 3 step sizes)
    laser, t, gt, odom, scans = _loop_log()
    params = SlamParams(particles=20, coarse_skip=coarse[0], coarse_levels=coarse[1])
    slam = make_slam("rbpf", laser, params, np.random.default_rng(5))
    est = _run(slam, t, odom, scans)
    err_odom = np.hypot(*(odom[:, :2] - gt[:, :2]).T)
    err_rbpf = np.hypot(*(est[:, :2] - gt[:, :2]).T)
    assert err_odom.max() > 0.5  # the odometry does drift
    assert err_rbpf.max() < 0.25 and err_rbpf.mean() < 0.1
    assert slam.updates > 10
    g = slam.occupancy()
    iy, ix = np.nonzero(g.occupied)
    x = g.origin[0] + (ix + 0.5) * g.resolution
    y = g.origin[1] + (iy + 0.5) * g.resolution
    d_wall = np.minimum.reduce([abs(x - 0), abs(x - 8), abs(y - 0), abs(y - 5)])
    assert np.mean(d_wall < 0.1) > 0.95  # the best particle's walls are where the room's are
    # in a room this small every scan rewrites every patch, so no sharing survives an update;
    # but patches left behind are recycled: no leak, the pool stays near the live set
    one_map = np.count_nonzero(slam.maps.tables[0] >= 0)
    own = sum(np.count_nonzero(slam.maps.tables[p] >= 0) for p in range(20))
    assert slam.maps.live_patches() <= own  # no patch alive that no particle's table holds
    assert slam.maps.capacity <= 2 * 20 * one_map + 256
    assert slam.maps.dropped == 0


def test_same_seed_same_result_other_seed_differs():
    laser, t, gt, odom, scans = _loop_log(0.3)
    params = SlamParams(particles=8)
    runs = []
    for seed in (1, 1, 2):
        slam = make_slam("rbpf", laser, params, np.random.default_rng(seed))
        est = _run(slam, t, odom, scans)
        runs.append((est, slam.occupancy().prob))
    assert np.array_equal(runs[0][0], runs[1][0])
    assert np.array_equal(runs[0][1], runs[1][1], equal_nan=True)
    assert not np.array_equal(runs[0][0], runs[2][0])


def test_estimate_is_correction_composed_with_odometry():
    laser, t, gt, odom, scans = _loop_log(0.3)
    slam = make_slam("rbpf", laser, SlamParams(particles=5), np.random.default_rng(0))
    for k in range(len(t)):
        updated = slam.process(t[k], odom[k], scans[k])
        assert np.allclose(slam.pose_estimate(), compose(slam.T_map_odom(), odom[k]))
        if k == 0:
            assert updated and np.allclose(slam.T_map_odom(), 0.0)  # map frame = first odom


def test_threads_do_not_change_the_result():
    # matching and registration on 2 threads: the same trajectory and every particle's map
    laser, t, gt, odom, scans = _loop_log(0.3)
    runs = []
    for threads in (1, 2):
        params = SlamParams(particles=6, threads=threads)
        slam = make_slam("rbpf", laser, params, np.random.default_rng(3))
        runs.append((_run(slam, t, odom, scans), [slam.maps.occupancy(k) for k in range(6)]))
        assert slam.updates > 5
    assert np.array_equal(runs[0][0], runs[1][0])
    for a, b in zip(runs[0][1], runs[1][1], strict=True):
        assert np.array_equal(a.prob, b.prob, equal_nan=True) and np.allclose(a.origin, b.origin)


def test_coarse_to_fine_changes_the_climb_and_is_checked():
    laser, t, gt, odom, scans = _loop_log(0.3)
    runs = []
    for coarse in ((0, 0), (1, 3)):
        params = SlamParams(particles=6, coarse_skip=coarse[0], coarse_levels=coarse[1])
        runs.append(
            _run(make_slam("rbpf", laser, params, np.random.default_rng(3)), t, odom, scans)
        )
    assert not np.array_equal(runs[0], runs[1])  # the setting reaches the matcher
    assert np.abs(runs[0] - runs[1])[:, :2].max() < 0.05  # and finds the same optimum nearly
    with pytest.raises(InputError, match="coarse_levels in"):
        SlamParams(coarse_skip=1, coarse_levels=6)  # more than the 5 step sizes there are
    with pytest.raises(InputError, match="coarse_skip must be >= 0"):
        SlamParams(coarse_skip=-1)
