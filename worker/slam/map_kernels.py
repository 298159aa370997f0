"""Numba kernels of the patch map: copy-on-write patches, scan registration, dense export.

The map of every particle is a table of patch ids into one shared pool of 32 x 32-cell
patches (GMapping's HierarchicalArray2D, patch magnitude 5). A patch referenced by several
particles is copied before a particle writes into it (GMapping copies the patches of the
active area before registering a scan); `counts` holds the exact reference counts.
Each cell keeps GMapping's PointAccumulator: hits, visits, and the sum of the hit points
(relative to the cell's lower-left corner, so float32 keeps sub-millimetre precision).
Beside the pool, `bits` (P, 2, 32) int64 holds per patch row two bit masks over the row's
cells, kept current by every write: OCCUPIED (hits / visits > 0.1) and FULL (>= 0.1). The
scan matcher reads these first and touches the pool only for occupied cells.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PATCH_BITS = 5
PATCH = 1 << PATCH_BITS  # [cells] patch side
PATCH_MASK = PATCH - 1
HITS, VISITS, ACC_X, ACC_Y = 0, 1, 2, 3  # channels of a pool cell
N_CHANNELS = 4
OCCUPIED, FULL = 0, 1  # bit-mask planes of `bits`
FULLNESS = 0.1  # GMapping's m_fullnessThreshold on hits / visits


@njit(cache=True)
def _writable_patch(pool, bits, counts, free_stack, n_free, table, tx, ty):
    """Patch id that this particle may write at table cell (tx, ty); -1 if the pool is full."""
    e = table[ty, tx]
    if e >= 0 and counts[e] == 1:
        return e
    if n_free[0] == 0:
        return -1
    n_free[0] -= 1
    new = free_stack[n_free[0]]
    if e < 0:
        pool[new] = 0.0
        bits[new] = 0
    else:
        pool[new] = pool[e]  # copy-on-write of a shared patch
        bits[new] = bits[e]
        counts[e] -= 1
    counts[new] = 1
    table[ty, tx] = new
    return new


@njit(cache=True, inline="always")
def _update_bits(pool, bits, e, ly, lx):
    """Refresh the OCCUPIED / FULL bits of cell (ly, lx) of patch e after a write."""
    hits = pool[e, ly, lx, HITS]
    limit = FULLNESS * pool[e, ly, lx, VISITS]
    bit = np.int64(1) << lx
    if hits > limit:
        bits[e, OCCUPIED, ly] |= bit
    else:
        bits[e, OCCUPIED, ly] &= ~bit
    if hits >= limit and hits > 0:
        bits[e, FULL, ly] |= bit
    else:
        bits[e, FULL, ly] &= ~bit


@njit(cache=True)
def _register_one(
    pool,
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
    Returns the number of cell updates dropped for lack of pool space (0 when the caller
    reserved enough patches).
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
                    e = _writable_patch(pool, bits, counts, free_stack, n_free, table, tx, ty)
            if e < 0:
                dropped += 1
            else:
                # unsigned indices: numba then skips its negative-index wraparound
                ue = np.uintp(e)
                ly = np.uintp(cy & PATCH_MASK)
                lx = np.uintp(cx & PATCH_MASK)
                pool[ue, ly, lx, VISITS] += 1.0
                if at_end:
                    pool[ue, ly, lx, HITS] += 1.0
                    pool[ue, ly, lx, ACC_X] += hx - cx * res
                    pool[ue, ly, lx, ACC_Y] += hy - cy * res
                    _update_bits(pool, bits, e, ly, lx)
                elif (bits[ue, FULL, ly] >> lx) & 1:
                    # a visit alone can only clear bits, and only of a cell that has them
                    _update_bits(pool, bits, e, ly, lx)
            if at_end:
                break
            e2 = 2 * err
            if e2 >= dy:
                err += dy
                cx += sx
            if e2 <= dx:
                err += dx
                cy += sy
    return dropped


@njit(cache=True)
def register_scans(
    pool,
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
    start,
):
    """Register the scan for particles start.. in turn; stop early when the pool runs short.

    need: (N,) patches a particle may have to allocate (its scan's bounding box). Returns
    (next particle to do, dropped cell updates); next < N means: grow the pool and call again.
    """
    dropped = 0
    for p in range(start, poses.shape[0]):
        if n_free[0] < need[p]:
            return p, dropped
        dropped += _register_one(
            pool,
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
    return poses.shape[0], dropped


@njit(cache=True)
def dense_prob(pool, table):
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
                    v = pool[e, ly, lx, VISITS]
                    if v > 0:
                        out[ty * PATCH + ly, tx * PATCH + lx] = pool[e, ly, lx, HITS] / v
    return out
