"""numba kernels for the relation generators: far pairs (SM), leave times (L), anchors (M)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def far_pair_counts(xy: np.ndarray, min_dist: float) -> np.ndarray:
    """counts (K,): for each i, how many j > i lie more than min_dist [m] from xy[i]."""
    k = xy.shape[0]
    d2 = min_dist * min_dist
    counts = np.zeros(k, dtype=np.int64)
    for i in range(k):
        c = 0
        xi = xy[i, 0]
        yi = xy[i, 1]
        for j in range(i + 1, k):
            dx = xy[j, 0] - xi
            dy = xy[j, 1] - yi
            if dx * dx + dy * dy > d2:
                c += 1
        counts[i] = c
    return counts


@njit(cache=True)
def far_pairs_fill(xy: np.ndarray, min_dist: float, counts: np.ndarray):
    """Index pairs (i (P,), j (P,)), i < j, of points more than min_dist apart, in row order;
    `counts` from `far_pair_counts` sizes the output so nothing is appended in the loop."""
    k = xy.shape[0]
    d2 = min_dist * min_dist
    total = 0
    for i in range(k):
        total += counts[i]
    out_i = np.empty(total, dtype=np.int64)
    out_j = np.empty(total, dtype=np.int64)
    p = 0
    for i in range(k):
        xi = xy[i, 0]
        yi = xy[i, 1]
        for j in range(i + 1, k):
            dx = xy[j, 0] - xi
            dy = xy[j, 1] - yi
            if dx * dx + dy * dy > d2:
                out_i[p] = i
                out_j[p] = j
                p += 1
    return out_i, out_j


@njit(cache=True)
def leave_index(xy: np.ndarray, away: float, limit: np.ndarray) -> np.ndarray:
    """leave (N,): the first index k > i at which the path is more than `away` [m] from
    xy[i], searched only up to limit[i] (the last pose that could close a loop with i);
    limit[i] + 1 when the robot stays within `away` until then."""
    n = xy.shape[0]
    a2 = away * away
    leave = np.empty(n, dtype=np.int64)
    for i in range(n):
        xi = xy[i, 0]
        yi = xy[i, 1]
        k = i + 1
        stop = min(limit[i], n - 1)
        while k <= stop:
            dx = xy[k, 0] - xi
            dy = xy[k, 1] - yi
            if dx * dx + dy * dy > a2:
                break
            k += 1
        leave[i] = k
    return leave


@njit(cache=True)
def distance_anchors(xy: np.ndarray, distance: float) -> np.ndarray:
    """Indices of the M anchors: pose 0, then each pose that lies at least `distance` [m]
    (Euclidean) from the previous anchor, which it replaces (thesis section 6.1)."""
    n = xy.shape[0]
    d2 = distance * distance
    out = np.empty(n, dtype=np.int64)
    if n == 0:
        return out
    out[0] = 0
    m = 1
    ax = xy[0, 0]
    ay = xy[0, 1]
    for k in range(1, n):
        dx = xy[k, 0] - ax
        dy = xy[k, 1] - ay
        if dx * dx + dy * dy >= d2:
            out[m] = k
            m += 1
            ax = xy[k, 0]
            ay = xy[k, 1]
    return out[:m]


@njit(cache=True)
def pair_deltas(poses: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """delta (P, 3) [x, y, theta]: inv(poses[i]) (+) poses[j] for each pair (se2.relative),
    in one pass without the temporaries numpy would allocate for millions of pairs."""
    p = i.shape[0]
    out = np.empty((p, 3))
    for k in range(p):
        a = i[k]
        b = j[k]
        c = math.cos(poses[a, 2])
        s = math.sin(poses[a, 2])
        dx = poses[b, 0] - poses[a, 0]
        dy = poses[b, 1] - poses[a, 1]
        out[k, 0] = c * dx + s * dy
        out[k, 1] = -s * dx + c * dy
        w = (poses[b, 2] - poses[a, 2] + math.pi) % (2.0 * math.pi) - math.pi
        out[k, 2] = w - 2.0 * math.pi if w >= math.pi else w
    return out
