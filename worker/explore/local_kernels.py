"""Numba kernels of the local costmap: its obstacle, near and inner layers and its costs."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worker.explore.costmap_kernels import INSCRIBED, LETHAL


def disc_half_widths(radius_cells: float) -> np.ndarray:
    """`(2R+1,) int64`: for each row offset dy = -R..R, the largest |dx| of a cell whose
    centre is within radius_cells of a centre (the disc of `disc_offsets`, row by row)."""
    r = int(math.floor(radius_cells))
    dy = np.arange(-r, r + 1)
    return np.floor(np.sqrt(np.maximum(radius_cells**2 + 1e-9 - dy * dy, 0.0))).astype(np.int64)


@njit(cache=True)
def _dilate_rows(cells, k, half_widths, n):
    """`(n, n) bool`: the union of discs (row half-widths `half_widths`) around cells[:k],
    by a difference array per row: 2 writes per disc row instead of one per disc cell."""
    r = half_widths.shape[0] // 2
    diff = np.zeros((n, n + 1), dtype=np.int32)
    for i in range(k):
        cy = cells[i, 0]
        cx = cells[i, 1]
        for m in range(half_widths.shape[0]):
            jy = cy + m - r
            if jy < 0 or jy >= n:
                continue
            hw = half_widths[m]
            a = max(0, cx - hw)
            b = min(n - 1, cx + hw)
            if a <= b:
                diff[jy, a] += 1
                diff[jy, b + 1] -= 1
    out = np.zeros((n, n), dtype=np.bool_)
    for iy in range(n):
        acc = 0
        for ix in range(n):
            acc += diff[iy, ix]
            out[iy, ix] = acc > 0
    return out


def disc_offsets(radius_cells: float) -> np.ndarray:
    """`(K, 2) int64 [dy, dx]` of the cells whose centres are within radius_cells of a centre."""
    r = int(math.floor(radius_cells))
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    keep = dx * dx + dy * dy <= radius_cells * radius_cells + 1e-9
    return np.column_stack((dy[keep], dx[keep])).astype(np.int64)


@njit(cache=True)
def local_layers(
    px, py, ox, oy, resolution, n, near_widths, inner_widths, g_lethal, g_cost, g_oy, g_ox,
    reach, rx, ry, rth, rhalf, clear_touching=False,
):  # fmt: skip
    """Local costmap of the window with lower-left corner (ox, oy), `n x n` cells.

    px, py: (K,) [m] obstacle points (map frame) from the recent scans; near_widths,
    inner_widths: `disc_half_widths` of the two layers' discs; the global costmap's
    obstacles `g_lethal` and costs `g_cost` are read through the window (its cell (0, 0) is
    global cell (g_oy, g_ox)). Returns `(lethal, near, inner, cost)`, all (n, n): lethal bool
    cells holding an obstacle (scan, or map within `reach` cells of the window's centre: the
    farthest a trajectory can take the footprint); near bool within the circumscribed radius
    (plus a cell) of one, where the footprint test must look closer; inner bool within the
    inscribed radius; cost uint8: the map's costs, raised to LETHAL / INSCRIBED by the layers.
    The robot stands where it is, so the space under its footprint (pose rx, ry, rth; half
    side rhalf) is free, and costmap_2d's footprint clearing leaves it so: the map's obstacle
    cells the footprint overlaps at all are artefacts (a wall drawn a cell too near by the
    SLAM map, which would otherwise forbid every motion, even backing away from it); scan
    cells are left out only when wholly under the footprint (a beam ending just at the
    robot's edge may be a real obstacle touching it), or, with clear_touching, when the
    footprint overlaps them at all (to find a way out once the robot touches something).
    """
    lethal = np.zeros((n, n), dtype=np.bool_)
    cells = np.empty((px.shape[0], 2), dtype=np.int64)
    k = 0
    c = math.cos(rth)
    s = math.sin(rth)
    # only cells wholly inside the footprint: one the robot's edge merely touches may be real
    lim = rhalf - 0.75 * resolution
    # a cell's half extent along the footprint's axes: cells overlapping the footprint are
    # those footprint_collides would report
    touch = rhalf + 0.5 * resolution * (abs(c) + abs(s))
    under = np.zeros((n, n), dtype=np.bool_)
    overlap = np.zeros((n, n), dtype=np.bool_)
    if rhalf > 0.0:
        b = int(math.ceil(2.0 * touch / resolution)) + 1
        ucy = int(math.floor((ry - oy) / resolution))
        ucx = int(math.floor((rx - ox) / resolution))
        for iy in range(max(0, ucy - b), min(n, ucy + b + 1)):
            dy = oy + (iy + 0.5) * resolution - ry
            for ix in range(max(0, ucx - b), min(n, ucx + b + 1)):
                dx = ox + (ix + 0.5) * resolution - rx
                u = abs(dx * c + dy * s)
                v = abs(-dx * s + dy * c)
                under[iy, ix] = u < lim and v < lim
                overlap[iy, ix] = u < touch and v < touch
    for i in range(px.shape[0]):
        ix = int(math.floor((px[i] - ox) / resolution))
        iy = int(math.floor((py[i] - oy) / resolution))
        if not (0 <= ix < n and 0 <= iy < n) or lethal[iy, ix] or under[iy, ix]:
            continue
        if not (clear_touching and overlap[iy, ix]):
            lethal[iy, ix] = True
            cells[k, 0] = iy
            cells[k, 1] = ix
            k += 1
    gh, gw = g_cost.shape
    c0 = n // 2 - reach
    c1 = n // 2 + reach + 1
    for iy in range(max(0, -g_oy, c0), min(n, gh - g_oy, c1)):
        for ix in range(max(0, -g_ox, c0), min(n, gw - g_ox, c1)):
            if g_lethal[g_oy + iy, g_ox + ix] and not lethal[iy, ix] and not overlap[iy, ix]:
                lethal[iy, ix] = True
                if k == cells.shape[0]:
                    c2 = np.empty((2 * k + 16, 2), dtype=np.int64)
                    c2[:k] = cells[:k]
                    cells = c2
                cells[k, 0] = iy
                cells[k, 1] = ix
                k += 1
    near = _dilate_rows(cells, k, near_widths, n)
    inner = _dilate_rows(cells, k, inner_widths, n)
    cost = np.zeros((n, n), dtype=np.uint8)
    for iy in range(n):
        gy = g_oy + iy
        for ix in range(n):
            if lethal[iy, ix]:
                cost[iy, ix] = LETHAL
            elif inner[iy, ix]:
                cost[iy, ix] = INSCRIBED
            else:
                gx = g_ox + ix
                if 0 <= gy < gh and 0 <= gx < gw:
                    cost[iy, ix] = g_cost[gy, gx]
    return lethal, near, inner, cost


@njit(cache=True)
def crossed_cells(ox, oy, resolution, n, px, py, theta, ranges, angles, range_max):
    """`(n, n) bool`: the cells of the window (lower-left corner (ox, oy)) that the beams of
    one scan from (px, py, theta) cross before their end cell, as costmap_2d's raytrace
    clears them. Beams without a return (>= range_max) clear nothing (costmap_2d drops
    them unless inf_is_valid); a beam's own end cell (its range nudged a fifth of a cell
    inside, as the marks are) is never cleared by it. The beam walk is
    `costmap_kernels.raytrace_scan`'s; it is not reused here because this runs every
    control step, and raytrace_scan over a window full of marks (keeping its box of
    changes, then its marking pass) takes twice as long (about 250 against 130 us a scan)."""
    out = np.zeros((n, n), dtype=np.bool_)
    for k in range(ranges.shape[0]):
        r = ranges[k]
        if not (r < range_max * 0.999) or r <= 0.0:
            continue
        c = math.cos(theta + angles[k])
        s = math.sin(theta + angles[k])
        step = resolution / max(abs(c), abs(s))
        re = r + 0.2 * resolution
        ex = int(math.floor((px + re * c - ox) / resolution))
        ey = int(math.floor((py + re * s - oy) / resolution))
        m = int(r / step)
        for i in range(m + 1):
            d = i * step
            ix = int(math.floor((px + d * c - ox) / resolution))
            iy = int(math.floor((py + d * s - oy) / resolution))
            if not (0 <= ix < n and 0 <= iy < n):
                break  # the window is convex: a beam that left it does not come back
            if ix == ex and iy == ey:
                break
            out[iy, ix] = True
    return out


@njit(cache=True)
def kept_marks(pts, ts, scans, t_min, crossed, ox, oy, resolution):
    """The marks `(K, 2) [x, y]` (with their times `ts (K,)` and scan numbers `scans (K,)`)
    seen after t_min whose cell is not marked in `crossed`, the `(n, n)` window of
    `crossed_cells` with lower-left corner (ox, oy) (points outside it are kept; a (0, 0)
    window clears nothing): the three arrays compacted, in their order."""
    n = crossed.shape[0]
    k = 0
    out_p = np.empty_like(pts)
    out_t = np.empty_like(ts)
    out_s = np.empty_like(scans)
    for i in range(pts.shape[0]):
        if not ts[i] > t_min:
            continue
        ix = int(math.floor((pts[i, 0] - ox) / resolution))
        iy = int(math.floor((pts[i, 1] - oy) / resolution))
        if 0 <= ix < n and 0 <= iy < n and crossed[iy, ix]:
            continue
        out_p[k, 0] = pts[i, 0]
        out_p[k, 1] = pts[i, 1]
        out_t[k] = ts[i]
        out_s[k] = scans[i]
        k += 1
    return out_p[:k], out_t[:k], out_s[:k]
