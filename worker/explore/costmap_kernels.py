"""Numba kernels of the costmap: costmap_2d inflation cost, bounded re-inflation, footprint test."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# the bounded exact distance transform, shared with the coverage's reachable cells
from worker.distance_kernels import inflate_region

# costmap_2d's cost values (costmap_2d/cost_values.h): one byte per cell.
FREE_SPACE = 0
INSCRIBED = 253  # the robot's centre here puts the footprint into an obstacle
LETHAL = 254  # an obstacle cell
NO_INFORMATION = 255  # unknown space


def inflation_cost(
    distance_m: float, inscribed_radius: float, cost_scaling_factor: float, inflation_radius: float
) -> int:
    """costmap_2d InflationLayer::computeCost for a cell `distance_m` from the nearest obstacle.

    0 -> LETHAL; <= inscribed radius -> INSCRIBED; else (INSCRIBED - 1) * exp(-k (d - r_in)),
    truncated to a byte as the C++ cast does; 0 beyond the inflation radius.
    """
    if distance_m == 0.0:
        return LETHAL
    if distance_m <= inscribed_radius:
        return INSCRIBED
    if distance_m > inflation_radius:
        return FREE_SPACE
    factor = math.exp(-cost_scaling_factor * (distance_m - inscribed_radius))
    return int((INSCRIBED - 1) * factor)


def effective_inflation_cells(
    resolution: float, inscribed_radius: float, cost_scaling_factor: float, inflation_radius: float
) -> int:
    """Radius in cells beyond which the inflation cost truncates to 0 (or the inflation radius).

    With the thesis's 7.5 scaling the cost is below 1 past ~0.94 m, well inside 2.25 m, so
    stamping farther would only write zeros.
    """
    r_zero = inscribed_radius + math.log(INSCRIBED - 1) / cost_scaling_factor
    r = min(inflation_radius, r_zero)
    return int(math.ceil(r / resolution)) + 1


def inflation_kernel(
    resolution: float, inscribed_radius: float, cost_scaling_factor: float, inflation_radius: float
) -> np.ndarray:
    """Cost stamp `(2R+1, 2R+1) uint8` around one obstacle cell; distances between cell centres."""
    r_cells = effective_inflation_cells(
        resolution, inscribed_radius, cost_scaling_factor, inflation_radius
    )
    kernel = np.zeros((2 * r_cells + 1, 2 * r_cells + 1), dtype=np.uint8)
    for dy in range(-r_cells, r_cells + 1):
        for dx in range(-r_cells, r_cells + 1):
            d = math.hypot(dx, dy) * resolution
            kernel[dy + r_cells, dx + r_cells] = inflation_cost(
                d, inscribed_radius, cost_scaling_factor, inflation_radius
            )
    return kernel


@njit(cache=True)
def footprint_collides(lethal, near, inner, origin_x, origin_y, resolution, x, y, theta, half):
    """True when the square footprint (half side `half` [m]) at (x, y, theta) overlaps an
    obstacle cell.

    lethal, near, inner: (H, W) bool layers of `local_kernels.local_layers`. A centre cell
    away from every obstacle (not near) is free without looking further; next to one (inner)
    it collides; in between, each obstacle cell under the footprint's bounding box gets an
    exact separating-axis test. Cells outside the grid count as free (the caller sizes the window).
    """
    h, w = lethal.shape
    ix = int(math.floor((x - origin_x) / resolution))
    iy = int(math.floor((y - origin_y) / resolution))
    if 0 <= ix < w and 0 <= iy < h:
        if not near[iy, ix]:
            return False
        if lethal[iy, ix] or inner[iy, ix]:
            return True
    c = math.cos(theta)
    s = math.sin(theta)
    ac = abs(c)
    as_ = abs(s)
    extent = half * (ac + as_)  # half side of the footprint's axis-aligned bounding box
    half_cell = 0.5 * resolution
    cell_on_axis = half_cell * (ac + as_)  # a cell's half extent along the footprint's axes
    x0 = max(0, int(math.floor((x - extent - origin_x) / resolution)))
    x1 = min(w - 1, int(math.floor((x + extent - origin_x) / resolution)))
    y0 = max(0, int(math.floor((y - extent - origin_y) / resolution)))
    y1 = min(h - 1, int(math.floor((y + extent - origin_y) / resolution)))
    for jy in range(y0, y1 + 1):
        dy = origin_y + (jy + 0.5) * resolution - y
        for jx in range(x0, x1 + 1):
            if not lethal[jy, jx]:
                continue
            dx = origin_x + (jx + 0.5) * resolution - x
            if abs(dx * c + dy * s) >= half + cell_on_axis:
                continue
            if abs(-dx * s + dy * c) >= half + cell_on_axis:
                continue
            return True
    return False


@njit(cache=True)
def first_colliding_pose(lethal, near, inner, origin_x, origin_y, resolution, poses, half):
    """Index of the first pose `(K, 3)` [x, y, theta] at which the square footprint (half
    side `half` [m]) overlaps an obstacle cell (`footprint_collides`), or -1."""
    for k in range(poses.shape[0]):
        if footprint_collides(
            lethal, near, inner, origin_x, origin_y, resolution,
            poses[k, 0], poses[k, 1], poses[k, 2], half,
        ):  # fmt: skip
            return k
    return -1


@njit(cache=True)
def inflate_tiles(lethal, kernel, cost, tiles, tile, ty0, ty1, tx0, tx1):
    """Re-inflate every `tile x tile` block within reach of a block flagged in `tiles`
    (the flags cleared here).

    tiles: (ceil(H / tile), ceil(W / tile)) bool, the blocks where obstacle cells went, all
    within the block range `[ty0, ty1) x [tx0, tx1)` (the updated window's: the work is the
    window's, not the map's). A cell's cost depends on the obstacles within R (the kernel's
    radius) only, so the blocks within ceil(R / tile) blocks of a flagged one are all that
    can change (from `lethal` alone: in any order); scattered changes recompute a few blocks.
    """
    h, w = lethal.shape
    th, tw = tiles.shape
    r = kernel.shape[0] // 2
    reach = (r + tile - 1) // tile
    oy0, oy1 = max(0, ty0 - reach), min(th, ty1 + reach)
    ox0, ox1 = max(0, tx0 - reach), min(tw, tx1 + reach)
    if oy1 <= oy0 or ox1 <= ox0:
        return
    todo = np.zeros((oy1 - oy0, ox1 - ox0), dtype=np.bool_)
    for ty in range(ty0, ty1):
        for tx in range(tx0, tx1):
            if tiles[ty, tx]:
                tiles[ty, tx] = False
                for uy in range(max(oy0, ty - reach), min(oy1, ty + reach + 1)):
                    for ux in range(max(ox0, tx - reach), min(ox1, tx + reach + 1)):
                        todo[uy - oy0, ux - ox0] = True
    # the blocks to do, in rectangles (a run along a row, grown down while the rows below
    # have the same run): one recomputation of a big rectangle costs far less than of its
    # blocks one by one (each looks R rows above and below itself)
    for ty in range(oy1 - oy0):
        for tx in range(ox1 - ox0):
            if not todo[ty, tx]:
                continue
            tx1 = tx
            while tx1 < ox1 - ox0 and todo[ty, tx1]:
                tx1 += 1
            ty1 = ty + 1
            while ty1 < oy1 - oy0 and todo[ty1, tx:tx1].all():
                ty1 += 1
            todo[ty:ty1, tx:tx1] = False
            inflate_region(
                lethal, kernel, cost, (oy0 + ty) * tile, min(h, (oy0 + ty1) * tile),
                (ox0 + tx) * tile, min(w, (ox0 + tx1) * tile),
            )  # fmt: skip


@njit(cache=True)
def stamp_fresh(lethal, kernel, cost, fresh, tiles, tile, ty0, ty1, tx0, tx1):
    """Raise the costs around the new obstacle cells (`fresh`, cleared here) of the blocks
    flagged in `tiles` (all within `[ty0, ty1) x [tx0, tx1)`; the flags cleared here), in place.

    A cost is the kernel's value at the nearest obstacle, the max over all of their stamps,
    so a new obstacle only raises costs: its stamp, max-ed in, is the exact update. Cells
    whose 4 neighbours are obstacles are never the nearest one to a free cell: no stamp.
    """
    h, w = lethal.shape
    r = kernel.shape[0] // 2
    for ty in range(max(0, ty0), min(tiles.shape[0], ty1)):
        for tx in range(max(0, tx0), min(tiles.shape[1], tx1)):
            if not tiles[ty, tx]:
                continue
            tiles[ty, tx] = False
            for sy in range(ty * tile, min(h, (ty + 1) * tile)):
                for sx in range(tx * tile, min(w, (tx + 1) * tile)):
                    if not fresh[sy, sx]:
                        continue
                    fresh[sy, sx] = False
                    if not lethal[sy, sx]:
                        continue
                    if (
                        0 < sy < h - 1
                        and 0 < sx < w - 1
                        and lethal[sy - 1, sx]
                        and lethal[sy + 1, sx]
                        and lethal[sy, sx - 1]
                        and lethal[sy, sx + 1]
                    ):
                        cost[sy, sx] = 254
                        continue
                    for iy in range(max(0, sy - r), min(h, sy + r + 1)):
                        krow = iy - sy + r
                        for ix in range(max(0, sx - r), min(w, sx + r + 1)):
                            c = kernel[krow, ix - sx + r]
                            if c > cost[iy, ix]:
                                cost[iy, ix] = c


@njit(cache=True)
def classify_region(
    prob, off_y, off_x, occupied_thresh, lethal, unknown, y0, y1, x0, x1, tiles, fresh,
    fresh_tiles, tile, obstacle, obstacle_min_prob=0.0,
):  # fmt: skip
    """Refresh the lethal/unknown layers from SLAM probabilities inside a window (in place).

    prob: (h, w) float32 occupancy probability, NaN unknown, whose cell (0, 0) is cell
    (off_y, off_x) of the layers; layer cells outside it are unknown. A cell is lethal above
    `occupied_thresh` (GMapping publishes 100 above its occ_thresh). The `tile x tile` blocks
    holding obstacle cells that went away are flagged in `tiles (ceil(H / tile),
    ceil(W / tile)) bool`; new obstacle cells in `fresh (H, W) bool`, their blocks in
    `fresh_tiles`. A cell the obstacle layer `obstacle (H, W) bool` marks is lethal too (the
    master grid takes the maximum of the layers), unless the map knows it with a
    probability under `obstacle_min_prob` (0: always). Returns the bounding boxes
    `(y0, y1, x0, x1)` of the lethal and of the unknown changes, each empty (y1 == y0) when
    nothing changed.
    """
    ph, pw = prob.shape
    ly0, ly1, lx0, lx1 = y1, y0, x1, x0
    uy0, uy1, ux0, ux1 = y1, y0, x1, x0
    for iy in range(y0, y1):
        sy = iy - off_y
        for ix in range(x0, x1):
            sx = ix - off_x
            p = prob[sy, sx] if (0 <= sy < ph and 0 <= sx < pw) else np.nan
            unk = math.isnan(p)
            let = ((not unk) and p > occupied_thresh) or (
                obstacle[iy, ix] and (unk or p >= obstacle_min_prob)
            )
            if let != lethal[iy, ix]:
                lethal[iy, ix] = let
                if let:
                    fresh[iy, ix] = True
                    fresh_tiles[iy // tile, ix // tile] = True
                else:
                    tiles[iy // tile, ix // tile] = True
                ly0 = min(ly0, iy)
                ly1 = max(ly1, iy + 1)
                lx0 = min(lx0, ix)
                lx1 = max(lx1, ix + 1)
            if unk != unknown[iy, ix]:
                unknown[iy, ix] = unk
                uy0 = min(uy0, iy)
                uy1 = max(uy1, iy + 1)
                ux0 = min(ux0, ix)
                ux1 = max(ux1, ix + 1)
    if ly1 <= ly0:
        ly0 = ly1 = lx0 = lx1 = 0
    if uy1 <= uy0:
        uy0 = uy1 = ux0 = ux1 = 0
    return ly0, ly1, lx0, lx1, uy0, uy1, ux0, ux1


@njit(cache=True)
def raytrace_scan(
    obstacle, origin_x, origin_y, resolution, px, py, theta, ranges, angles, range_max,
    obstacle_range, raytrace_range,
):  # fmt: skip
    """costmap_2d's obstacle layer on one scan, in place on `obstacle (H, W) bool`.

    Beams without a return (>= range_max) are dropped, as costmap_2d drops them. Each other
    beam first clears the cells it crosses up to min(range, raytrace_range), its end cell
    excluded (raytrace clearing: a mark a later beam passes through goes), then marks its end
    cell when the range is within obstacle_range (nudged a fifth of a cell inside the
    obstacle, so that rounding cannot put the mark in the free cell in front). Returns the
    bounding box `(y0, y1, x0, x1)` of the cells that changed (empty when y1 == y0).
    """
    h, w = obstacle.shape
    y0, y1, x0, x1 = h, 0, w, 0
    for k in range(ranges.shape[0]):
        r = ranges[k]
        if not (r < range_max * 0.999) or r <= 0.0:
            continue
        c, s = math.cos(theta + angles[k]), math.sin(theta + angles[k])
        # one cell along the beam's major axis per step, as Bresenham's line walks it
        step = resolution / max(abs(c), abs(s))
        re = r + 0.2 * resolution
        ex = int(math.floor((px + re * c - origin_x) / resolution))
        ey = int(math.floor((py + re * s - origin_y) / resolution))
        n = int(min(r, raytrace_range) / step)
        for i in range(n + 1):
            d = i * step
            ix = int(math.floor((px + d * c - origin_x) / resolution))
            iy = int(math.floor((py + d * s - origin_y) / resolution))
            if (ix == ex and iy == ey) or not (0 <= ix < w and 0 <= iy < h):
                continue
            if obstacle[iy, ix]:
                obstacle[iy, ix] = False
                y0, y1, x0, x1 = min(y0, iy), max(y1, iy + 1), min(x0, ix), max(x1, ix + 1)
    for k in range(ranges.shape[0]):
        r = ranges[k]
        if not (r < range_max * 0.999) or r <= 0.0 or r > obstacle_range:
            continue
        re = r + 0.2 * resolution
        ix = int(math.floor((px + re * math.cos(theta + angles[k]) - origin_x) / resolution))
        iy = int(math.floor((py + re * math.sin(theta + angles[k]) - origin_y) / resolution))
        if 0 <= ix < w and 0 <= iy < h and not obstacle[iy, ix]:
            obstacle[iy, ix] = True
            y0, y1, x0, x1 = min(y0, iy), max(y1, iy + 1), min(x0, ix), max(x1, ix + 1)
    if y1 <= y0:
        return 0, 0, 0, 0
    return y0, y1, x0, x1
