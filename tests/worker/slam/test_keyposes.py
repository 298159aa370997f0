"""The final trajectory from key poses: the blend between two keys, a particle filter's lineage
read back, and rbpf's final trajectory along its best particle."""

from __future__ import annotations

import numpy as np

from worker.slam.keyposes import Lineage, between_keys
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan


def test_a_scan_between_two_keys_is_blended_by_the_path_travelled():
    # odometry along x: scans at x = 0, 1, 2, 3; keys at scans 0 and 2, the second key moved
    # 0.2 m to the left by the final estimate
    odom = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], dtype=float)
    path = np.array([0.0, 1.0, 2.0, 3.0])
    keys = np.array([[0, 0, 0], [2, 0.2, 0]], dtype=float)
    out = between_keys(keys, odom[[0, 2]], path[[0, 2]], odom, np.array([0, 0, 1, 1]), path)
    # scan 1: from key 0 (1, 0), from key 1 (1, 0.2), half way: (1, 0.1); scan 3 from key 1
    np.testing.assert_allclose(out, [[0, 0, 0], [1, 0.1, 0], [2, 0.2, 0], [3, 0.2, 0]])


def test_a_turned_key_carries_the_odometry_in_its_own_frame():
    odom = np.array([[0, 0, 0], [1, 0, 0]], dtype=float)
    keys = np.array([[5, 5, np.pi / 2]])  # the map frame turned a quarter and moved
    out = between_keys(keys, odom[:1], np.zeros(1), odom, np.array([0, 0]), np.array([0, 1.0]))
    np.testing.assert_allclose(out, [[5, 5, np.pi / 2], [5, 6, np.pi / 2]], atol=1e-12)


def test_scans_before_the_first_key_keep_their_odometry():
    odom = np.array([[0.5, 0.1, 0.2]])
    out = between_keys(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), odom, np.array([-1]), [0])
    np.testing.assert_array_equal(out, odom)


def test_a_lineage_reads_a_particle_back_through_its_parents():
    lin = Lineage()
    p0 = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=float)
    p1, p2 = p0 + 10, p0 + 20
    for poses, parents in ((p0, None), (p1, None), (p2, np.array([2, 2, 0]))):
        lin.scan(np.zeros(3))
        lin.update(poses, parents)
    # particle 1 of the last update descends from particle 2 of the one before, and so on
    np.testing.assert_array_equal(lin.path(1), [p0[2], p1[2], p2[1]])
    np.testing.assert_array_equal(lin.path(2), [p0[0], p1[0], p2[2]])


def _run(seed: int, steps: int = 40):
    """rbpf over a walk in a box with noisy odometry, its history copied forward by the
    test: every particle's whole path, extended or copied at each update."""
    laser = Laser()
    params = SlamParams(particles=8, linear_update=0.2, resample_threshold=0.9)
    slam = make_slam("rbpf", laser, params, np.random.default_rng(seed))
    rng = np.random.default_rng(seed + 100)
    histories: list[list[np.ndarray]] = [[] for _ in range(params.particles)]
    odom = np.array([1.5, 2.5, 0.0])
    truth = odom.copy()
    for k in range(steps):
        if k:
            step = np.array([0.12, 0.0, 0.03])
            truth = truth + [step[0] * np.cos(truth[2]), step[0] * np.sin(truth[2]), step[2]]
            noisy = step * (1 + rng.normal(0, 0.1, 3))
            odom = odom + [noisy[0] * np.cos(odom[2]), noisy[0] * np.sin(odom[2]), noisy[2]]
        before = slam.updates
        slam.process(0.1 * k, odom, box_scan(truth, laser.angles))
        if slam.updates > before:
            parents = slam.lineage._parents[-1]
            if parents is not None:
                histories = [list(histories[j]) for j in parents]
            for i in range(params.particles):
                histories[i].append(slam.poses[i].copy())
    return slam, histories


def test_rbpf_final_trajectory_follows_the_best_particle_back_through_resamplings():
    slam, histories = _run(seed=3)
    assert slam.resamplings >= 2  # the test means something only if ancestors were dropped
    best = int(np.argmax(slam.log_weight_sums))
    np.testing.assert_array_equal(slam.lineage.path(best), np.array(histories[best]))
    final = slam.final_trajectory()
    assert final.shape == (40, 3)
    # the last scan's final pose is the best particle's, as the online estimate has it then
    np.testing.assert_allclose(final[-1], slam.pose_estimate(), atol=1e-12)
