"""Sparse pose-graph optimisation on SE(2): Levenberg-Marquardt with scipy.sparse, a Huber
kernel on the edges marked robust (Grisetti, Kuemmerle, Stachniss, Burgard 2010, "A tutorial
on graph-based SLAM", eqs. 30-35 and the SE(2) Jacobians of its section IV)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from worker.evaluate.se2 import wrap_angle

PRIOR_WEIGHT = 1e8  # information of the prior that holds node 0 where it is (the gauge)


@dataclass(frozen=True, eq=False)
class Edges:
    """E constraints z_ij = the pose of node j seen from node i.

    i, j: (E,) int64; z: (E, 3) [x, y, theta]; sigma: (E, 3) [m, m, rad] standard deviations
    (diagonal information 1 / sigma^2); robust: (E,) bool, Huber kernel on these.
    frame: (E,) [rad] or None (all zero): sigma's x and y are along axes turned by this from
    z's frame (a corridor closure: one sigma along the corridor, one across it).
    """

    i: np.ndarray
    j: np.ndarray
    z: np.ndarray
    sigma: np.ndarray
    robust: np.ndarray
    frame: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class OptimizeResult:
    """Optimised poses (N, 3), the cost before and after, iterations run."""

    poses: np.ndarray
    cost_initial: float
    cost_final: float
    iterations: int


def edge_errors(poses: np.ndarray, e: Edges) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Whitened errors (E, 3) of e_ij = t2v(Z_ij^-1 X_i^-1 X_j) / sigma, and the Jacobians
    (E, 3, 3) of the whitened errors with respect to x_i and x_j."""
    xi, xj = poses[e.i], poses[e.j]
    ci, si = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    cz, sz = np.cos(e.z[:, 2]), np.sin(e.z[:, 2])
    dx, dy = xj[:, 0] - xi[:, 0], xj[:, 1] - xi[:, 1]
    # R_i^T (t_j - t_i) and its derivative by theta_i
    lx, ly = ci * dx + si * dy, -si * dx + ci * dy
    dlx, dly = -si * dx + ci * dy, -ci * dx - si * dy
    ux, uy = lx - e.z[:, 0], ly - e.z[:, 1]
    err = np.empty((len(e.i), 3))
    err[:, 0] = cz * ux + sz * uy
    err[:, 1] = -sz * ux + cz * uy
    err[:, 2] = wrap_angle(xj[:, 2] - xi[:, 2] - e.z[:, 2])
    # R_z^T R_i^T as a 2x2 per edge: rows of M
    m = np.empty((len(e.i), 2, 2))
    m[:, 0, 0], m[:, 0, 1] = cz * ci - sz * si, cz * si + sz * ci
    m[:, 1, 0], m[:, 1, 1] = -(sz * ci + cz * si), -sz * si + cz * ci
    a = np.zeros((len(e.i), 3, 3))
    b = np.zeros((len(e.i), 3, 3))
    a[:, :2, :2] = -m
    a[:, 0, 2] = cz * dlx + sz * dly
    a[:, 1, 2] = -sz * dlx + cz * dly
    a[:, 2, 2] = -1.0
    b[:, :2, :2] = m
    b[:, 2, 2] = 1.0
    if e.frame is not None and np.any(e.frame != 0.0):
        _turn_xy(e.frame, err, a, b)
    w = 1.0 / e.sigma
    return err * w, a * w[:, :, None], b * w[:, :, None]


def _turn_xy(frame: np.ndarray, err: np.ndarray, a: np.ndarray, b: np.ndarray) -> None:
    """Express the xy rows of the errors (E, 3) and Jacobians (E, 3, 3) in axes turned by
    frame (E,) [rad], in place."""
    c, s = np.cos(frame), np.sin(frame)
    for arr in (err, a, b):
        x, y = arr[:, 0].copy(), arr[:, 1].copy()
        cc = c if arr.ndim == 2 else c[:, None]
        ss = s if arr.ndim == 2 else s[:, None]
        arr[:, 0] = cc * x + ss * y
        arr[:, 1] = -ss * x + cc * y


def huber_weights(err_w: np.ndarray, robust: np.ndarray, delta: float) -> np.ndarray:
    """(E,) IRLS weights: 1 inside delta (in sigmas), delta / |e| outside, on robust edges."""
    norm = np.sqrt((err_w**2).sum(axis=1))
    w = np.ones(len(norm))
    out = robust & (norm > delta)
    w[out] = delta / norm[out]
    return w


def total_cost(err_w: np.ndarray, robust: np.ndarray, delta: float) -> float:
    """Sum of squared whitened errors, Huber's rho(s) = 2 delta sqrt(s) - delta^2 past delta."""
    s = (err_w**2).sum(axis=1)
    rho = np.where(robust & (s > delta * delta), 2.0 * delta * np.sqrt(s) - delta * delta, s)
    return float(rho.sum())


def _normal_equations(poses: np.ndarray, e: Edges, delta: float):
    err, a, b = edge_errors(poses, e)
    w = huber_weights(err, e.robust, delta)
    n = poses.shape[0] * 3
    jac = np.concatenate([a, b], axis=2)  # (E, 3, 6)
    h_blocks = np.einsum("eki,ekj->eij", jac, jac) * w[:, None, None]  # (E, 6, 6)
    g_blocks = np.einsum("eki,ek->ei", jac, err) * w[:, None]  # (E, 6)
    idx = np.concatenate([3 * e.i[:, None] + np.arange(3), 3 * e.j[:, None] + np.arange(3)], 1)
    rows = np.repeat(idx, 6, axis=1).ravel()
    cols = np.tile(idx, (1, 6)).ravel()
    hess = sp.coo_matrix((h_blocks.ravel(), (rows, cols)), shape=(n, n)).tocsc()
    grad = np.bincount(idx.ravel(), weights=g_blocks.ravel(), minlength=n)
    return hess, grad, total_cost(err, e.robust, delta)


def optimize(
    poses: np.ndarray, edges: Edges, huber_delta: float, iterations: int, tolerance: float
) -> OptimizeResult:
    """Minimise the sum of (robust) squared whitened edge errors over the poses (N, 3),
    node 0 held fixed; Levenberg-Marquardt damping on the diagonal (Marquardt's scaling)."""
    x = np.array(poses, dtype=np.float64, copy=True)
    n = x.shape[0]
    if len(edges.i) == 0 or n < 2:
        return OptimizeResult(x, 0.0, 0.0, 0)
    hess, grad, cost = _normal_equations(x, edges, huber_delta)
    cost0, lam, it = cost, 1e-4, 0
    prior = sp.csc_matrix((np.full(3, PRIOR_WEIGHT), (np.arange(3), np.arange(3))), (3 * n, 3 * n))
    while it < iterations:
        it += 1
        diag = sp.diags(lam * (hess.diagonal() + 1e-9))
        step = spla.spsolve((hess + prior + diag).tocsc(), -grad)
        trial = x + step.reshape(n, 3)
        trial[:, 2] = wrap_angle(trial[:, 2])
        t_hess, t_grad, t_cost = _normal_equations(trial, edges, huber_delta)
        if t_cost < cost:
            done = cost - t_cost < tolerance * max(cost, 1e-12)
            x, hess, grad, cost = trial, t_hess, t_grad, t_cost
            lam = max(lam / 10.0, 1e-9)
            if done:
                break
        else:
            lam *= 10.0
            if lam > 1e6:
                break
    return OptimizeResult(x, cost0, cost, it)
