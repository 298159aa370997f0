"""Numba kernels of the door passage: the obstacles on either side of a line, across it."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# a cell counts as across the path from a point when the direction to it lies within this
# angle of the path's normal [rad]: a door crossed up to 60 degrees off its axis still has its
# jambs across the path, a wall straight ahead of the path has not
ACROSS_PATH = math.tan(math.radians(60.0))
# across a door's own axis: its cross-section, give or take the rounding of its cells
ACROSS_AXIS = math.tan(math.radians(20.0))


@njit(cache=True)
def nearest_sides(cx, cy, ux, uy, lethal, ox, oy, res, radius, cone):
    """The obstacle cells of `lethal` nearest to the point (cx, cy) [m] on the left and on
    the right of the line through it along the unit (ux, uy), among the cells within
    `radius` [m] whose direction from the point lies within atan(cone) of the line's normal
    (cell centres, half a cell of slack; grid origin (ox, oy), cell size res). Returns
    (lx, ly, ld, rx, ry, rd): each side's cell centre and its distance, ld / rd inf where a
    side has none."""
    h, w = lethal.shape
    r = int(radius / res) + 1
    icx = int(math.floor((cx - ox) / res))
    icy = int(math.floor((cy - oy) / res))
    lx = ly = rx = ry = 0.0
    ld = rd = np.inf
    for iy in range(max(0, icy - r), min(h, icy + r + 1)):
        dy = oy + (iy + 0.5) * res - cy
        for ix in range(max(0, icx - r), min(w, icx + r + 1)):
            if not lethal[iy, ix]:
                continue
            dx = ox + (ix + 0.5) * res - cx
            d = math.hypot(dx, dy)
            if d > radius:
                continue
            along = dx * ux + dy * uy
            side = ux * dy - uy * dx  # > 0: left of the line
            if abs(along) > cone * abs(side) + 0.5 * res:
                continue  # ahead or behind, not across (half a cell of slack for rounding)
            if side >= 0.0 and d < ld:
                lx, ly, ld = dx + cx, dy + cy, d
            if side <= 0.0 and d < rd:
                rx, ry, rd = dx + cx, dy + cy, d
    return lx, ly, ld, rx, ry, rd


@njit(cache=True)
def gaps_along(px, py, lethal, ox, oy, res, radius, cone):
    """For each point of the path (px, py) [m], `nearest_sides` across the path's direction
    there: `(K, 6)` rows (lx, ly, ld, rx, ry, rd)."""
    k = px.shape[0]
    out = np.full((k, 6), np.inf)
    for i in range(k):
        j0 = max(0, i - 1)
        j1 = min(k - 1, i + 1)
        dx = px[j1] - px[j0]
        dy = py[j1] - py[j0]
        norm = math.hypot(dx, dy)
        if norm == 0.0:
            continue
        lx, ly, ld, rx, ry, rd = nearest_sides(
            px[i], py[i], dx / norm, dy / norm, lethal, ox, oy, res, radius, cone
        )
        out[i, 0] = lx
        out[i, 1] = ly
        out[i, 2] = ld
        out[i, 3] = rx
        out[i, 4] = ry
        out[i, 5] = rd
    return out
