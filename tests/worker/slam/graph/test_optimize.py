"""The pose-graph optimiser on hand-made graphs with solutions derived by hand."""

from __future__ import annotations

import numpy as np

from worker.evaluate.se2 import relative, wrap_angle
from worker.slam.graph.optimize import Edges, edge_errors, optimize


def _edges(rows, robust=None):
    i = np.array([r[0] for r in rows])
    j = np.array([r[1] for r in rows])
    z = np.array([r[2] for r in rows], dtype=float)
    sigma = np.array([r[3] for r in rows], dtype=float)
    rob = np.zeros(len(rows), bool) if robust is None else np.asarray(robust)
    return Edges(i, j, z, sigma, rob)


def test_square_with_perturbed_start_converges_to_the_true_square():
    # a unit square driven counter-clockwise: the four edges agree with one solution
    truth = np.array([[0, 0, 0], [1, 0, np.pi / 2], [1, 1, np.pi], [0, 1, -np.pi / 2]], float)
    rows = [(k, (k + 1) % 4, relative(truth[k], truth[(k + 1) % 4]), (0.1, 0.1, 0.05))
            for k in range(4)]  # fmt: skip
    start = truth + np.array([[0, 0, 0], [0.2, -0.1, 0.1], [-0.3, 0.2, -0.2], [0.1, 0.3, 0.15]])
    res = optimize(start, _edges(rows), 1.0, 50, 1e-12)
    assert np.allclose(res.poses[:, :2], truth[:, :2], atol=1e-6)
    assert np.allclose(wrap_angle(res.poses[:, 2] - truth[:, 2]), 0, atol=1e-6)
    assert res.cost_final < 1e-9 < res.cost_initial


def test_two_disagreeing_edges_meet_at_their_weighted_mean():
    # z = 1.0 (sigma 0.1) and z = 1.3 (sigma 0.2) along x: x1 is their inverse-variance
    # weighted mean (1.0 / 0.01 + 1.3 / 0.04) / (1 / 0.01 + 1 / 0.04)
    rows = [(0, 1, (1.0, 0, 0), (0.1, 0.1, 0.1)), (0, 1, (1.3, 0, 0), (0.2, 0.2, 0.1))]
    res = optimize(np.zeros((2, 3)), _edges(rows), 1.0, 20, 1e-14)
    assert abs(res.poses[1, 0] - (100 * 1.0 + 25 * 1.3) / 125) < 1e-6
    assert np.allclose(res.poses[0], 0) and abs(res.poses[1, 1]) < 1e-9


def test_huber_kernel_limits_the_pull_of_a_wrong_loop_edge():
    # chain 0 -> 1 -> 2 of 1 m steps, a loop edge 0 -> 2 claiming 3 m, sigma 0.1 m for all.
    # Least squares: x1 = 4/3, x2 = 8/3. Huber (delta = 1 sigma) on the loop edge: its pull is
    # capped at delta / sigma, so x2 - x1 - 1 = delta * sigma, x2 = 2 x1: x1 = 1.1, x2 = 2.2.
    s = (0.1, 0.1, 0.1)
    rows = [(0, 1, (1, 0, 0), s), (1, 2, (1, 0, 0), s), (0, 2, (3, 0, 0), s)]
    start = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    plain = optimize(start, _edges(rows), 1.0, 50, 1e-14)
    assert np.allclose(plain.poses[1:, 0], [4 / 3, 8 / 3], atol=1e-6)
    robust = optimize(start, _edges(rows, [False, False, True]), 1.0, 100, 1e-15)
    assert np.allclose(robust.poses[1:, 0], [1.1, 2.2], atol=1e-4)


def test_jacobians_match_finite_differences():
    rng = np.random.default_rng(3)
    poses = rng.normal(size=(2, 3))
    e = _edges([(0, 1, rng.normal(size=3), (0.1, 0.2, 0.05))])
    _, a, b = edge_errors(poses, e)
    eps = 1e-7
    for node, jac in ((0, a[0]), (1, b[0])):
        for d in range(3):
            p1, p0 = poses.copy(), poses.copy()
            p1[node, d] += eps
            p0[node, d] -= eps
            num = (edge_errors(p1, e)[0][0] - edge_errors(p0, e)[0][0]) / (2 * eps)
            assert np.allclose(num, jac[:, d], atol=1e-5)


def test_a_turned_edge_frame_leaves_its_free_axis_to_the_other_edges():
    # edge A: z = (1, 0.5, 0), sigma 0.1 on each axis. Edge B (a corridor closure):
    # z = (2, 0, 0) with sigma 10 m along one axis and 0.01 m across it.
    # frame 0: B is free along x and holds y: x1 = 1 (A alone), y1 = the weighted mean
    # (100 * 0.5 + 10^4 * 0) / (100 + 10^4 + 0.01) of A's and B's y;
    # frame pi / 2: B's free axis is y: x1 = (100 * 1 + 10^4 * 2) / (100 + 10^4 + 0.01),
    # y1 = 0.5 (A alone, up to B's 0.01 weight)
    def solve(frame: float) -> np.ndarray:
        a = _edges([(0, 1, (1.0, 0.5, 0), (0.1, 0.1, 0.1)), (0, 1, (2.0, 0, 0), (10, 0.01, 0.1))])
        e = Edges(a.i, a.j, a.z, a.sigma, a.robust, np.array([0.0, frame]))
        return optimize(np.zeros((2, 3)), e, 1.0, 30, 1e-15).poses[1]

    w_a, w_b, w_free = 1 / 0.1**2, 1 / 0.01**2, 1 / 10.0**2
    x, y, _ = solve(0.0)
    assert abs(x - (w_a * 1.0 + w_free * 2.0) / (w_a + w_free)) < 1e-6
    assert abs(y - w_a * 0.5 / (w_a + w_b)) < 1e-6
    x, y, _ = solve(np.pi / 2)
    assert abs(x - (w_a * 1.0 + w_b * 2.0) / (w_a + w_b)) < 1e-6
    assert abs(y - w_a * 0.5 / (w_a + w_free)) < 1e-6
