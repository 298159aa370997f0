"""Numba kernel of the graph SLAM's map: every node's scan ray-cast into dense hit / visit
counts at its (optimised) pose, GMapping's counting model (a beam's cells are visited, its
end cell hit), so the published map means what rbpf's does."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def register_scans(hits, visits, ix0, iy0, res, poses, ranges, cos_a, sin_a, usable, max_range):
    """Add the scans ranges (N, B) taken at poses (N, 3) to hits / visits (H, W) float32,
    whose cell (0, 0) is the global cell (ix0, iy0) (global cell = floor(xy / res)).

    Beams of 0, NaN or past max_range are ignored; beams past `usable` are cut there and leave
    no hit (GMapping's registerScan). Cells outside the arrays are skipped.
    """
    h, w = hits.shape
    for k in range(poses.shape[0]):
        x, y, th = poses[k, 0], poses[k, 1], poses[k, 2]
        c, s = math.cos(th), math.sin(th)
        x0 = int(math.floor(x / res))
        y0 = int(math.floor(y / res))
        for b in range(ranges.shape[1]):
            d = ranges[k, b]
            if not (d > 0.0) or d > max_range:
                continue
            hit = True
            if d >= usable:
                d = usable
                hit = False
            ca = c * cos_a[b] - s * sin_a[b]
            sa = s * cos_a[b] + c * sin_a[b]
            x1 = int(math.floor((x + d * ca) / res))
            y1 = int(math.floor((y + d * sa) / res))
            dx, dy = abs(x1 - x0), -abs(y1 - y0)
            sx = 1 if x1 > x0 else -1
            sy = 1 if y1 > y0 else -1
            err = dx + dy
            cx, cy = x0, y0
            while True:
                at_end = cx == x1 and cy == y1
                if at_end and not hit:
                    break
                lx, ly = cx - ix0, cy - iy0
                if 0 <= lx < w and 0 <= ly < h:
                    visits[ly, lx] += 1.0
                    if at_end:
                        hits[ly, lx] += 1.0
                if at_end:
                    break
                e2 = 2 * err
                if e2 >= dy:
                    err += dy
                    cx += sx
                if e2 <= dx:
                    err += dx
                    cy += sy


@njit(cache=True)
def hit_ratio(hits, visits):
    """(H, W) float32 hits / visits, NaN where never visited."""
    h, w = hits.shape
    out = np.empty((h, w), dtype=np.float32)
    for iy in range(h):
        for ix in range(w):
            v = visits[iy, ix]
            out[iy, ix] = hits[iy, ix] / v if v > 0 else np.nan
    return out
