"""Numba kernels of the patch map: copy-on-write patches, scan registration, dense export.

The map of every particle is a table of patch ids into one shared pool of 32 x 32-cell
patches (GMapping's HierarchicalArray2D, patch magnitude 5). A patch referenced by several
particles is copied before a particle writes into it (GMapping copies the patches of the
active area before registering a scan); `counts` holds the exact reference counts.
Each cell keeps GMapping's PointAccumulator, stored as separate planes of the pool so that
each pass touches only what it needs: `visits` (P, 32, 32) float32 (the only plane a free
cell's update writes), `hits` (P, 32, 32) float32 and `mean` (P, 32, 32, 2) float32, the
running mean of the hit points relative to the cell's lower-left corner [m] (what the scan
matcher reads; float32 keeps sub-millimetre precision there).
Beside them, `bits` (P, 2, 32) int64 holds per patch row two bit masks over the row's
cells, kept current by every write: OCCUPIED (hits / visits > 0.1) and FULL (>= 0.1). The
scan matcher reads these first and touches `mean` only for occupied cells.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PATCH_BITS = 5
PATCH = 1 << PATCH_BITS  # [cells] patch side
PATCH_MASK = PATCH - 1
OCCUPIED, FULL = 0, 1  # bit-mask planes of `bits`
FULLNESS = 0.1  # GMapping's m_fullnessThreshold on hits / visits


@njit(cache=True)
def _writable_patch(visits, hits, mean, bits, counts, free_stack, n_free, table, tx, ty):
    """Patch id that this particle may write at table cell (tx, ty); -1 if the pool is full."""
    e = table[ty, tx]
    if e >= 0 and counts[e] == 1:
        return e
    if n_free[0] == 0:
        return -1
    n_free[0] -= 1
    new = free_stack[n_free[0]]
    if e < 0:
        visits[new] = 0.0
        hits[new] = 0.0
        mean[new] = 0.0
        bits[new] = 0
    else:
        visits[new] = visits[e]  # copy-on-write of a shared patch
        hits[new] = hits[e]
        mean[new] = mean[e]
        bits[new] = bits[e]
        counts[e] -= 1
    counts[new] = 1
    table[ty, tx] = new
    return new


@njit(cache=True, inline="always")
def _update_bits(visits, hits, bits, e, ly, lx):
    """Refresh the OCCUPIED / FULL bits of cell (ly, lx) of patch e after a write."""
    h = hits[e, ly, lx]
    limit = FULLNESS * visits[e, ly, lx]
    bit = np.int64(1) << lx
    if h > limit:
        bits[e, OCCUPIED, ly] |= bit
    else:
        bits[e, OCCUPIED, ly] &= ~bit
    if h >= limit and h > 0:
        bits[e, FULL, ly] |= bit
    else:
        bits[e, FULL, ly] &= ~bit


@njit(cache=True)
def _register_one(
    visits,
    hits,
    mean,
    bits,
    counts,
    free_stack,
    n_free,
    table,
    tpx0,
    tpy0,
    pose,
    ranges,
    cos_a,
    sin_a,
    res,
    usable_range,
    max_range,
):
    """Integrate one scan into one particle's map (GMapping ScanMatcher::registerScan).

    Beams longer than max_range (or 0 / NaN) are ignored; beams longer than usable_range are
    cut to it and mark free cells only. Cells on the Bresenham line before the end cell get
    one visit; the end cell, for a beam shorter than usable_range, a hit at the end point.
    The Bresenham steps are branch-free (selects), the patch is looked up only when the line
    leaves one. Returns the number of cell updates dropped for lack of pool space (0 when
    the caller reserved enough patches).
    """
    th, tw = table.shape
    x, y, theta = pose[0], pose[1], pose[2]
    c, s = np.cos(theta), np.sin(theta)
    x0 = int(np.floor(x / res))
    y0 = int(np.floor(y / res))
    dropped = 0
    for i in range(ranges.shape[0]):
        d = ranges[i]
        if not (d > 0.0) or d > max_range:
            continue
        hit = True
        if d >= usable_range:
            d = usable_range
            hit = False
        ca = c * cos_a[i] - s * sin_a[i]
        sa = s * cos_a[i] + c * sin_a[i]
        hx = x + d * ca
        hy = y + d * sa
        x1 = int(np.floor(hx / res))
        y1 = int(np.floor(hy / res))
        # Bresenham from (x0, y0) to (x1, y1), all octants
        dx = abs(x1 - x0)
        dy = -abs(y1 - y0)
        sx = 1 if x1 > x0 else -1
        sy = 1 if y1 > y0 else -1
        err = dx + dy
        cx, cy = x0, y0
        last_tx, last_ty, e = -(1 << 30), -(1 << 30), -1
        while True:
            at_end = cx == x1 and cy == y1
            if at_end and not hit:
                break
            tx = (cx >> PATCH_BITS) - tpx0
            ty = (cy >> PATCH_BITS) - tpy0
            if tx != last_tx or ty != last_ty:
                last_tx, last_ty = tx, ty
                e = -1
                if 0 <= tx < tw and 0 <= ty < th:
                    e = table[ty, tx]
                    if e < 0 or counts[e] != 1:  # a call costs more than the checks
                        e = _writable_patch(
                            visits, hits, mean, bits, counts, free_stack, n_free, table, tx, ty
                        )
            if e < 0:
                dropped += 1
            else:
                # unsigned indices: numba then skips its negative-index wraparound
                ue = np.uintp(e)
                ly = np.uintp(cy & PATCH_MASK)
                lx = np.uintp(cx & PATCH_MASK)
                visits[ue, ly, lx] += 1.0
                if at_end:
                    h = hits[ue, ly, lx] + 1.0
                    hits[ue, ly, lx] = h
                    # running mean of the hit points (GMapping keeps their sum)
                    mean[ue, ly, lx, 0] += (hx - cx * res - mean[ue, ly, lx, 0]) / h
                    mean[ue, ly, lx, 1] += (hy - cy * res - mean[ue, ly, lx, 1]) / h
                    _update_bits(visits, hits, bits, ue, ly, lx)
                elif (bits[ue, FULL, ly] >> lx) & 1:
                    # a visit alone can only clear bits, and only of a cell that has them
                    _update_bits(visits, hits, bits, ue, ly, lx)
            if at_end:
                break
            e2 = 2 * err
            step_x = e2 >= dy
            step_y = e2 <= dx
            err += (dy if step_x else 0) + (dx if step_y else 0)
            cx += sx if step_x else 0
            cy += sy if step_y else 0
    return dropped


@njit(cache=True)
def register_scans(
    visits,
    hits,
    mean,
    bits,
    counts,
    free_stack,
    n_free,
    tables,
    tpx0,
    tpy0,
    poses,
    ranges,
    cos_a,
    sin_a,
    res,
    usable_range,
    max_range,
    need,
    todo,
    start,
):
    """Register the scan for particles todo[start:] in turn; stop early when the pool runs
    short.

    need: (N,) patches a particle may have to allocate (its scan's bounding box). Returns
    (next position in todo, dropped cell updates); next < len(todo) means: grow the pool and
    call again.
    """
    dropped = 0
    for k in range(start, todo.shape[0]):
        p = todo[k]
        if n_free[0] < need[p]:
            return k, dropped
        dropped += _register_one(
            visits,
            hits,
            mean,
            bits,
            counts,
            free_stack,
            n_free,
            tables[p],
            tpx0,
            tpy0,
            poses[p],
            ranges,
            cos_a,
            sin_a,
            res,
            usable_range,
            max_range,
        )
    return todo.shape[0], dropped


@njit(cache=True)
def dense_hits(hits, table):
    """(TH*32, TW*32) float32 end-point counts of one particle's map, 0 where none."""
    th, tw = table.shape
    out = np.zeros((th * PATCH, tw * PATCH), dtype=np.float32)
    for ty in range(th):
        for tx in range(tw):
            e = table[ty, tx]
            if e < 0:
                continue
            out[ty * PATCH : (ty + 1) * PATCH, tx * PATCH : (tx + 1) * PATCH] = hits[e]
    return out


@njit(cache=True)
def dense_prob(visits, hits, table):
    """(TH*32, TW*32) float32 hits / visits of one particle's map, NaN where never visited."""
    th, tw = table.shape
    out = np.full((th * PATCH, tw * PATCH), np.nan, dtype=np.float32)
    for ty in range(th):
        for tx in range(tw):
            e = table[ty, tx]
            if e < 0:
                continue
            for ly in range(PATCH):
                for lx in range(PATCH):
                    v = visits[e, ly, lx]
                    if v > 0:
                        out[ty * PATCH + ly, tx * PATCH + lx] = hits[e, ly, lx] / v
    return out
