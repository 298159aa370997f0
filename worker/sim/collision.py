"""Footprint collision and collision-checked motion kernels (numba).

The robot is a square footprint rotated with its heading; it collides when the square overlaps
an occupied cell (separating-axis test, exact) or leaves the grid (the border is a wall).
"""

from __future__ import annotations

import math

from numba import njit


@njit(cache=True, nogil=True)
def footprint_collides(occ, resolution, origin_x, origin_y, x, y, theta, half_side):
    """True if the square of half side `half_side` [m] centred at (x, y), rotated by `theta`,
    overlaps an occupied cell of `occ` `(H, W)` (bottom row first) or pokes out of the grid."""
    height, width = occ.shape
    c = math.cos(theta)
    s = math.sin(theta)
    ac = abs(c)
    as_ = abs(s)
    extent = half_side * (ac + as_)  # half width of the footprint's axis-aligned bounding box
    gx0 = (x - extent - origin_x) / resolution
    gy0 = (y - extent - origin_y) / resolution
    gx1 = (x + extent - origin_x) / resolution
    gy1 = (y + extent - origin_y) / resolution
    if gx0 < 0.0 or gy0 < 0.0 or gx1 > width or gy1 > height:
        return True
    ix0 = int(math.floor(gx0))
    iy0 = int(math.floor(gy0))
    ix1 = min(int(math.floor(gx1)), width - 1)
    iy1 = min(int(math.floor(gy1)), height - 1)
    half_cell = 0.5 * resolution
    # The cell's half extent projected on the footprint's own axes (same for both axes).
    cell_on_axis = half_cell * (ac + as_)
    for iy in range(iy0, iy1 + 1):
        for ix in range(ix0, ix1 + 1):
            if not occ[iy, ix]:
                continue
            # Cell bounds overlap the bounding box by construction (x, y axes); test the two
            # footprint axes u = (c, s), v = (-s, c) (separating axis theorem).
            dx = origin_x + (ix + 0.5) * resolution - x
            dy = origin_y + (iy + 0.5) * resolution - y
            if abs(dx * c + dy * s) >= half_side + cell_on_axis:
                continue
            if abs(-dx * s + dy * c) >= half_side + cell_on_axis:
                continue
            # Strict overlap also on the world axes (touching faces is not a collision).
            if abs(dx) >= extent + half_cell or abs(dy) >= extent + half_cell:
                continue
            return True
    return False


@njit(cache=True, nogil=True)
def advance(occ, resolution, origin_x, origin_y, x, y, theta, v, w, dt, half_side):
    """Move at constant (v [m/s], w [rad/s]) for dt [s] on exact arcs, in sub-steps small enough
    (half a cell at the footprint's corners) that the robot cannot tunnel through a thin wall.

    Returns (x, y, theta, blocked, t_contact): on contact the robot stays at the last free
    sub-step pose and `t_contact` [s] is the time into the step at which it was blocked.
    """
    corner = half_side * math.sqrt(2.0)
    sweep = abs(v) * dt + abs(w) * dt * corner  # [m] bound on how far any footprint point moves
    n_sub = max(1, int(math.ceil(sweep / (0.5 * resolution))))
    h = dt / n_sub
    for k in range(n_sub):
        if abs(w) > 1e-9:
            # Exact unicycle arc over h.
            nt = theta + w * h
            nx = x + v / w * (math.sin(nt) - math.sin(theta))
            ny = y - v / w * (math.cos(nt) - math.cos(theta))
        else:
            nt = theta
            nx = x + v * h * math.cos(theta)
            ny = y + v * h * math.sin(theta)
        if footprint_collides(occ, resolution, origin_x, origin_y, nx, ny, nt, half_side):
            return x, y, theta, True, k * h
        x, y, theta = nx, ny, nt
    return x, y, theta, False, dt
