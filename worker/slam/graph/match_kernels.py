"""Numba kernels of the correlative scan matcher: scan points, smeared grids, max-pooled
pyramids, branch-and-bound over (angle, x, y) and a sub-cell refinement.

The score of a pose is Karto's response: the mean, over the scan's points placed at the pose,
of a grid holding at each cell exp(-d^2 / (2 sigma^2)) for the distance d to the nearest map
point (the "smear", kept as a maximum over points within 2 sigma). Level k of the pyramid holds
at cell (iy, ix) the maximum of the grid over cells [iy, iy + 2^k) x [ix, ix + 2^k), so the
score of an offset at level k bounds the scores of every offset of its 2^k x 2^k block
(Cartographer's precomputation grid, Hess et al. 2016), which is what branch-and-bound needs.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

DISTANCE_PENALTY_GAIN = 0.2  # Karto's ScanMatcher DISTANCE_PENALTY_GAIN
ANGLE_PENALTY_GAIN = 0.2  # Karto's ANGLE_PENALTY_GAIN


@njit(cache=True)
def scan_points(ranges, cos_a, sin_a, max_use, spacing):
    """(M, 2) float64 points in the robot frame of the beams with 0 < range < max_use [m],
    each at least `spacing` [m] from the previous point kept (a cheap voxel filter)."""
    n = ranges.shape[0]
    out = np.empty((n, 2))
    m = 0
    px, py = 1e18, 1e18
    s2 = spacing * spacing
    for b in range(n):
        r = ranges[b]
        if not (r > 0.0 and r < max_use):
            continue
        x, y = r * cos_a[b], r * sin_a[b]
        if (x - px) ** 2 + (y - py) ** 2 < s2:
            continue
        out[m, 0], out[m, 1] = x, y
        px, py = x, y
        m += 1
    return out[:m].copy()


@njit(cache=True)
def smear_grid(points, ox, oy, res, h, w, sigma):
    """(h, w) float32 grid with origin (ox, oy) [m]: exp(-d^2 / 2 sigma^2) to the nearest of
    the map-frame `points` (K, 2), within a kernel of radius 2 sigma (at least one cell)."""
    grid = np.zeros((h, w), dtype=np.float32)
    rad = max(1, int(math.ceil(2.0 * sigma / res)))
    inv2s2 = 1.0 / (2.0 * sigma * sigma)
    for k in range(points.shape[0]):
        fx = (points[k, 0] - ox) / res
        fy = (points[k, 1] - oy) / res
        cx, cy = int(math.floor(fx)), int(math.floor(fy))
        for iy in range(max(0, cy - rad), min(h, cy + rad + 1)):
            dy = (iy + 0.5 - fy) * res
            for ix in range(max(0, cx - rad), min(w, cx + rad + 1)):
                dx = (ix + 0.5 - fx) * res
                v = math.exp(-(dx * dx + dy * dy) * inv2s2)
                if v > grid[iy, ix]:
                    grid[iy, ix] = v
    return grid


@njit(cache=True)
def max_pyramid(grid, depth):
    """(depth + 1, h, w) float32: level k = max of `grid` over the 2^k x 2^k block whose
    lower-left cell is (iy, ix) (cells past the border count as 0)."""
    h, w = grid.shape
    pyr = np.zeros((depth + 1, h, w), dtype=np.float32)
    pyr[0] = grid
    for k in range(1, depth + 1):
        s = 1 << (k - 1)
        prev = pyr[k - 1]
        cur = pyr[k]
        for iy in range(h):
            for ix in range(w):
                v = prev[iy, ix]
                if ix + s < w and prev[iy, ix + s] > v:
                    v = prev[iy, ix + s]
                if iy + s < h:
                    if prev[iy + s, ix] > v:
                        v = prev[iy + s, ix]
                    if ix + s < w and prev[iy + s, ix + s] > v:
                        v = prev[iy + s, ix + s]
                cur[iy, ix] = v
    return pyr


@njit(cache=True, inline="always")
def _level_score(level, size, cx, cy, ox, oy):
    """Mean of `level` (block maxima over size x size) at the cells + (ox, oy). A block that
    starts left of or below the grid but reaches into it reads the border cell, whose block
    covers it (a looser, still valid bound)."""
    h, w = level.shape
    total = 0.0
    for m in range(cx.shape[0]):
        ix, iy = cx[m] + ox, cy[m] + oy
        if -size < ix < 0:
            ix = 0
        if -size < iy < 0:
            iy = 0
        if 0 <= ix < w and 0 <= iy < h:
            total += level[iy, ix]
    return total / max(1, cx.shape[0])


@njit(cache=True)
def _rotated_cells(points, prior, angles, ox, oy, res):
    """(A, M) int64 cells of the points rotated by each angle and placed at the prior's xy."""
    na, m = angles.shape[0], points.shape[0]
    cx = np.empty((na, m), dtype=np.int64)
    cy = np.empty((na, m), dtype=np.int64)
    for a in range(na):
        c, s = math.cos(angles[a]), math.sin(angles[a])
        for k in range(m):
            x = prior[0] + c * points[k, 0] - s * points[k, 1]
            y = prior[1] + s * points[k, 0] + c * points[k, 1]
            cx[a, k] = int(math.floor((x - ox) / res))
            cy[a, k] = int(math.floor((y - oy) / res))
    return cx, cy


@njit(cache=True, inline="always")
def _nearest_zero(lo, hi):
    """The value of [lo, hi] closest to 0."""
    if lo <= 0 <= hi:
        return 0
    return lo if lo > 0 else hi


@njit(cache=True, inline="always")
def _distance_factor(lo_x, hi_x, lo_y, hi_y, res, penalty):
    """Karto's distance penalty, at its mildest over the block of offsets [lo, hi] [cells]:
    max(min, 1 - 0.2 d^2 / variance); penalty = (variance [m^2], minimum), variance <= 0: none."""
    if penalty[0] <= 0.0:
        return 1.0
    nx, ny = _nearest_zero(lo_x, hi_x) * res, _nearest_zero(lo_y, hi_y) * res
    return max(penalty[1], 1.0 - DISTANCE_PENALTY_GAIN * (nx * nx + ny * ny) / penalty[0])


@njit(cache=True, inline="always")
def _angle_factor(dtheta, penalty):
    """Karto's angle penalty max(min, 1 - 0.2 dtheta^2 / variance); penalty = (variance
    [rad^2], minimum), variance <= 0: none."""
    if penalty[0] <= 0.0:
        return 1.0
    return max(penalty[1], 1.0 - ANGLE_PENALTY_GAIN * dtheta * dtheta / penalty[0])


@njit(cache=True, inline="always")
def _excluded(lo_x, hi_x, lo_y, hi_y, exclude):
    """Whether the whole block of offsets [lo, hi] [cells] lies within the disc exclude =
    (x, y, radius) [cells] (radius < 0: nothing is excluded)."""
    r2 = exclude[2] * exclude[2]
    if exclude[2] < 0:
        return False
    for x in (lo_x, hi_x):
        for y in (lo_y, hi_y):
            if (x - exclude[0]) ** 2 + (y - exclude[1]) ** 2 > r2:
                return False
    return True


@njit(cache=True)
def branch_and_bound(
    pyr, ox, oy, res, points, prior, window, angles, min_score, dist_penalty, angle_penalty,
    exclude,
):  # fmt: skip
    """Best (score, angle, dx, dy) over the angles (A,) [rad] and the cell offsets within
    +-window [cells] of the prior's xy, depth-first best-first as Cartographer's
    FastCorrelativeScanMatcher2D; (-1, 0, 0, 0) when nothing reaches min_score.

    The response is multiplied by Karto's penalties for leaving the prior (dist_penalty,
    angle_penalty: (variance, minimum) pairs, see _distance_factor); a block's bound takes the
    mildest penalty of its offsets, so it still bounds every offset inside it. Offsets within
    the disc exclude = (dx, dy, radius) [cells] are not candidates (radius < 0: none), which
    finds the best match somewhere else (the ambiguity check of a loop closure).
    """
    depth = pyr.shape[0] - 1
    cx, cy = _rotated_cells(points, prior, angles, ox, oy, res)
    a_fac = np.empty(angles.shape[0])
    for a in range(angles.shape[0]):
        a_fac[a] = _angle_factor(angles[a] - prior[2], angle_penalty)
    step = 1 << depth
    n_side = (2 * window) // step + 1
    n_top = angles.shape[0] * n_side * n_side
    cap = n_top + 4 * (depth + 1) + 4
    st_a = np.empty(cap, dtype=np.int64)
    st_x = np.empty(cap, dtype=np.int64)
    st_y = np.empty(cap, dtype=np.int64)
    st_l = np.empty(cap, dtype=np.int64)
    st_s = np.empty(cap)
    top_s = np.empty(n_top)
    k = 0
    for a in range(angles.shape[0]):
        for i in range(n_side):
            for j in range(n_side):
                x, y = -window + i * step, -window + j * step
                st_a[k], st_x[k], st_y[k], st_l[k] = a, x, y, depth
                hx, hy = min(window, x + step - 1), min(window, y + step - 1)
                f = a_fac[a] * _distance_factor(x, hx, y, hy, res, dist_penalty)
                top_s[k] = f * _level_score(pyr[depth], step, cx[a], cy[a], x, y)
                k += 1
    order = np.argsort(top_s)  # ascending: the best candidate is popped first
    st_a[:n_top], st_x[:n_top] = st_a[:n_top][order], st_x[:n_top][order]
    st_y[:n_top], st_l[:n_top] = st_y[:n_top][order], st_l[:n_top][order]
    st_s[:n_top] = top_s[order]
    n = n_top
    best, best_a, best_x, best_y = min_score, -1, 0, 0
    child_s = np.empty(4)
    child_o = np.empty((4, 2), dtype=np.int64)
    while n > 0:
        n -= 1
        a, x, y, lvl, s = st_a[n], st_x[n], st_y[n], st_l[n], st_s[n]
        if s <= best:
            continue
        if lvl == 0:
            if not _excluded(x, x, y, y, exclude):
                best, best_a, best_x, best_y = s, a, x, y
            continue
        half = 1 << (lvl - 1)
        nc = 0
        for di in range(2):
            for dj in range(2):
                xx, yy = x + di * half, y + dj * half
                if xx > window or yy > window:
                    continue
                hx, hy = min(window, xx + half - 1), min(window, yy + half - 1)
                if _excluded(xx, hx, yy, hy, exclude):
                    continue
                child_o[nc, 0], child_o[nc, 1] = xx, yy
                f = a_fac[a] * _distance_factor(xx, hx, yy, hy, res, dist_penalty)
                child_s[nc] = f * _level_score(pyr[lvl - 1], half, cx[a], cy[a], xx, yy)
                nc += 1
        idx = np.argsort(child_s[:nc])
        for q in range(nc):
            c = idx[q]
            if child_s[c] > best:
                st_a[n], st_x[n], st_y[n] = a, child_o[c, 0], child_o[c, 1]
                st_l[n], st_s[n] = lvl - 1, child_s[c]
                n += 1
    if best_a < 0:
        return -1.0, 0.0, 0, 0
    return best, angles[best_a], best_x, best_y


@njit(cache=True)
def bilinear_score(grid, ox, oy, res, points, x0, y0, th):
    """Mean bilinearly interpolated grid value at the points placed at pose (x0, y0, th)."""
    h, w = grid.shape
    c, s = math.cos(th), math.sin(th)
    total = 0.0
    for k in range(points.shape[0]):
        fx = (x0 + c * points[k, 0] - s * points[k, 1] - ox) / res - 0.5
        fy = (y0 + s * points[k, 0] + c * points[k, 1] - oy) / res - 0.5
        ix, iy = int(math.floor(fx)), int(math.floor(fy))
        if ix < 0 or iy < 0 or ix + 1 >= w or iy + 1 >= h:
            continue
        ax, ay = fx - ix, fy - iy
        v0 = grid[iy, ix] * (1 - ax) + grid[iy, ix + 1] * ax
        v1 = grid[iy + 1, ix] * (1 - ax) + grid[iy + 1, ix + 1] * ax
        total += v0 * (1 - ay) + v1 * ay
    return total / max(1, points.shape[0])


@njit(cache=True, inline="always")
def _penalised(grid, ox, oy, res, points, x, y, th, prior, dist_pen, ang_pen):
    f = _angle_factor(th - prior[2], ang_pen)
    if dist_pen[0] > 0.0:
        d2 = (x - prior[0]) ** 2 + (y - prior[1]) ** 2
        f *= max(dist_pen[1], 1.0 - DISTANCE_PENALTY_GAIN * d2 / dist_pen[0])
    return f * bilinear_score(grid, ox, oy, res, points, x, y, th)


@njit(cache=True)
def refine(
    grid, ox, oy, res, points, pose, lin_step, ang_step, halvings, prior, dist_pen, ang_pen,
    lin_half, ang_half,
):  # fmt: skip
    """Hill climbing from `pose` on the bilinearly interpolated grid, with the penalties for
    leaving `prior` (as branch_and_bound): move to the best of the 26 neighbours at
    (lin_step [m], ang_step [rad]) while it improves, then halve the steps, `halvings` times
    (GMapping's scan matcher optimisation, over the three axes at once). It stays within the
    search window, +-lin_half [m] in x and y and +-ang_half [rad] of `prior`."""
    x, y, th = pose[0], pose[1], pose[2]
    best = _penalised(grid, ox, oy, res, points, x, y, th, prior, dist_pen, ang_pen)
    ls, as_ = lin_step, ang_step
    for _ in range(halvings + 1):
        for _moves in range(20):
            bx, by, bt, improved = x, y, th, False
            for i in range(-1, 2):
                for j in range(-1, 2):
                    for q in range(-1, 2):
                        if i == 0 and j == 0 and q == 0:
                            continue
                        cx, cy, ct = x + j * ls, y + q * ls, th + i * as_
                        if (
                            abs(cx - prior[0]) > lin_half
                            or abs(cy - prior[1]) > lin_half
                            or abs(ct - prior[2]) > ang_half
                        ):
                            continue
                        s = _penalised(grid, ox, oy, res, points, cx, cy, ct, prior, dist_pen,
                                       ang_pen)  # fmt: skip
                        if s > best:
                            best, bx, by, bt, improved = s, cx, cy, ct, True
            if not improved:
                break
            x, y, th = bx, by, bt
        ls *= 0.5
        as_ *= 0.5
    return np.array([x, y, th]), best


@njit(cache=True)
def point_normals(points, max_gap):
    """(M, 2) unit normals of the scan points (in scan order) from their neighbours closer
    than max_gap [m]; (0, 0) for an isolated point."""
    m = points.shape[0]
    out = np.zeros((m, 2))
    g2 = max_gap * max_gap
    for k in range(m):
        a, b = k, k
        if (
            k > 0
            and (points[k, 0] - points[k - 1, 0]) ** 2 + (points[k, 1] - points[k - 1, 1]) ** 2 < g2
        ):
            a = k - 1
        if (
            k + 1 < m
            and (points[k, 0] - points[k + 1, 0]) ** 2 + (points[k, 1] - points[k + 1, 1]) ** 2 < g2
        ):
            b = k + 1
        tx, ty = points[b, 0] - points[a, 0], points[b, 1] - points[a, 1]
        n = math.sqrt(tx * tx + ty * ty)
        if n > 0:
            out[k, 0], out[k, 1] = -ty / n, tx / n
    return out
