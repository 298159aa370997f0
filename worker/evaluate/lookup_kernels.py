"""numba kernels: pose lookup by timestamp and the per-relation error of the Kuemmerle metric."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worker.evaluate.se2_scalar import wrap as _wrap

# Two timestamps closer than this [s] are the same sample: relation files carry 6 decimals
# (CARMEN's microseconds), so a written-and-read time differs from the original by <= 5e-7 s.
TIME_TOL_S = 1e-5


@njit(cache=True)
def _locate(tp: np.ndarray, q: float, scale: float) -> int:
    """Index i with t[i] <= q < t[i+1] (t = tp[:, 0]); -1 before the first sample, n-1 at or
    after the last.

    The search starts where q would sit if samples were evenly spaced (they are, at 10 Hz,
    in every log we write) and gallops outwards, so it costs O(1) on even sampling and
    O(log n) otherwise, instead of a cache-missing binary search over the whole array.
    """
    n = tp.shape[0]
    if n == 0 or q < tp[0, 0]:
        return -1
    if q >= tp[n - 1, 0]:
        return n - 1
    g = int((q - tp[0, 0]) * scale)
    g = min(max(g, 0), n - 2)
    step = 1
    if tp[g, 0] <= q:
        lo = g
        hi = g + 1
        while tp[hi, 0] <= q:  # stops: t[n-1] > q
            lo = hi
            step *= 2
            hi = min(lo + step, n - 1)
    else:
        hi = g
        lo = g - 1
        while tp[lo, 0] > q:  # stops: t[0] <= q
            hi = lo
            step *= 2
            lo = max(hi - step, 0)
    while hi - lo > 1:  # invariant t[lo] <= q < t[hi]
        mid = (lo + hi) >> 1
        if tp[mid, 0] <= q:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, inline="always")
def _pose_at(tp, q, scale, max_gap, tol):
    """(ok, x, y, theta) of the trajectory `tp (N, 4) [t, x, y, theta]` at time q: an exact
    sample, else the SE(2) interpolation between the two neighbours when both lie within
    max_gap of q. Time and pose share a row so that a lookup touches one cache line."""
    n = tp.shape[0]
    i = _locate(tp, q, scale)
    if i >= 0 and q - tp[i, 0] <= tol:
        return True, tp[i, 1], tp[i, 2], tp[i, 3]
    if i + 1 < n and tp[i + 1, 0] - q <= tol:
        return True, tp[i + 1, 1], tp[i + 1, 2], tp[i + 1, 3]
    if i < 0 or i + 1 >= n:
        return False, 0.0, 0.0, 0.0
    t0 = tp[i, 0]
    t1 = tp[i + 1, 0]
    if q - t0 > max_gap + tol or t1 - q > max_gap + tol:
        return False, 0.0, 0.0, 0.0
    # translation linear, angle along the shorter arc (se2.interpolate)
    a = (q - t0) / (t1 - t0)
    x = tp[i, 1] + a * (tp[i + 1, 1] - tp[i, 1])
    y = tp[i, 2] + a * (tp[i + 1, 2] - tp[i, 2])
    th = _wrap(tp[i, 3] + a * _wrap(tp[i + 1, 3] - tp[i, 3]))
    return True, x, y, th


@njit(cache=True, inline="always")
def _scale(tp: np.ndarray) -> float:
    n = tp.shape[0]
    if n < 2 or tp[n - 1, 0] <= tp[0, 0]:
        return 0.0
    return (n - 1) / (tp[n - 1, 0] - tp[0, 0])


@njit(cache=True)
def lookup_poses(tp, q, max_gap, tol):
    """Poses `(M, 3)` of `tp (N, 4) [t, x, y, theta]` at the query times `q (M,)`, and
    `ok (M,)`; rows with ok False are 0."""
    m = q.shape[0]
    out = np.zeros((m, 3))
    ok = np.zeros(m, dtype=np.bool_)
    scale = _scale(tp)
    for k in range(m):
        found, x, y, th = _pose_at(tp, q[k], scale, max_gap, tol)
        if found:
            ok[k] = True
            out[k, 0] = x
            out[k, 1] = y
            out[k, 2] = th
    return out, ok


@njit(cache=True)
def relation_errors(tp, t1, t2, delta, max_gap, tol):
    """Per-relation errors of the estimate `tp (N, 4) [t, x, y, theta]` on relations
    `(t1 (M,), t2 (M,), delta (M, 3))`: translation |d.xy - d*.xy| [m], rotation
    |wrap(d.theta - d*.theta)| [rad] with d = inv(X(t1)) X(t2), and ok (M,).

    Both norms equal those of inv(d*) d (Kuemmerle 2009): R(d*.theta)^T only rotates the
    translation difference. Skipped relations (a pose not found) get 0 and ok False.
    """
    m = t1.shape[0]
    err_t = np.zeros(m)
    err_r = np.zeros(m)
    ok = np.zeros(m, dtype=np.bool_)
    scale = _scale(tp)
    for k in range(m):
        f1, x1, y1, th1 = _pose_at(tp, t1[k], scale, max_gap, tol)
        if not f1:
            continue
        f2, x2, y2, th2 = _pose_at(tp, t2[k], scale, max_gap, tol)
        if not f2:
            continue
        c = math.cos(th1)
        s = math.sin(th1)
        dx = x2 - x1
        dy = y2 - y1
        ex = c * dx + s * dy - delta[k, 0]
        ey = -s * dx + c * dy - delta[k, 1]
        err_t[k] = math.sqrt(ex * ex + ey * ey)
        err_r[k] = abs(_wrap(th2 - th1 - delta[k, 2]))
        ok[k] = True
    return err_t, err_r, ok
