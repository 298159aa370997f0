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
from numba import njit, prange

PATCH_BITS = 5
PATCH = 1 << PATCH_BITS  # [cells] patch side
PATCH_MASK = PATCH - 1
OCCUPIED, FULL = 0, 1  # bit-mask planes of `bits`
FULLNESS = 0.1  # GMapping's m_fullnessThreshold on hits / visits


@njit(cache=True, nogil=True)
def _writable_patch(visits, hits, mean, bits, counts, free_stack, n_free, table, tx, ty, dirty):
    """Patch id that this particle may write at table cell (tx, ty); -1 if the pool is full.
    A patch allocated there marks the cell in `dirty` (TH, TW) bool."""
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
    dirty[ty, tx] = True
    return new


@njit(cache=True, nogil=True, inline="always")
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


@njit(cache=True, nogil=True, inline="always")
def _beam_end(x, y, c, s, cos_ai, sin_ai, d, res):
    """(hx, hy, x1, y1): the end point [m] of a beam of length d from (x, y) with heading
    cos / sin (c, s) and beam angle cos / sin (cos_ai, sin_ai), and its cell."""
    hx = x + d * (c * cos_ai - s * sin_ai)
    hy = y + d * (s * cos_ai + c * sin_ai)
    return hx, hy, int(np.floor(hx / res)), int(np.floor(hy / res))


@njit(cache=True, nogil=True)
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
    dirty,
    may_allocate=True,
):
    """Integrate one scan into one particle's map (GMapping ScanMatcher::registerScan).

    Beams longer than max_range (or 0 / NaN) are ignored; beams longer than usable_range are
    cut to it and mark free cells only. Cells on the Bresenham line before the end cell get
    one visit; the end cell, for a beam shorter than usable_range, a hit at the end point.
    The Bresenham steps are branch-free (selects), the patch is looked up only when the line
    leaves one. Returns the number of cell updates dropped for lack of pool space (0 when
    the caller reserved enough patches). may_allocate False (the patches were claimed
    beforehand, `claim_patches`; particles registered in parallel): a patch not this
    particle's alone is not written, and its updates count as dropped. Every table cell whose
    patch is written is marked in `dirty` (TH, TW) bool (the incremental map assembly's cue).
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
        hx, hy, x1, y1 = _beam_end(x, y, c, s, cos_a[i], sin_a[i], d, res)
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
                        if may_allocate:
                            e = _writable_patch(
                                visits, hits, mean, bits, counts, free_stack, n_free, table,
                                tx, ty, dirty,
                            )  # fmt: skip
                        else:
                            e = -1
                    if e >= 0:
                        dirty[ty, tx] = True
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


@njit(cache=True, nogil=True)
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
    dirty,
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
            dirty,
        )
    return todo.shape[0], dropped


@njit(cache=True, nogil=True)
def _line_patches(mark, out, n, tx0, ty0, a0, b0, a1, b1, swap):
    """Add to out[:n] (marking them in `mark`) the table cells of the patches a Bresenham
    line from cell (a0, b0) to (a1, b1) may touch (a the major axis; swap: a is y); returns
    the new n. Per patch column along the major axis, the line's cells lie within half a
    cell of the straight line between the end cells (Bresenham's error bound), so the minor
    range taken, that +-1 cell, holds them."""
    th, tw = mark.shape
    da = a1 - a0
    db = b1 - b0
    a_lo, a_hi = min(a0, a1), max(a0, a1)
    b_lo, b_hi = min(b0, b1), max(b0, b1)
    for pa in range(a_lo >> PATCH_BITS, (a_hi >> PATCH_BITS) + 1):
        ca = max(a_lo, pa << PATCH_BITS)
        cb = min(a_hi, (pa << PATCH_BITS) + PATCH_MASK)
        if da == 0:
            m0, m1 = b_lo, b_hi
        else:
            u = b0 + db * (ca - a0) / da
            v = b0 + db * (cb - a0) / da
            m0 = max(b_lo, int(np.floor(min(u, v))) - 1)
            m1 = min(b_hi, int(np.ceil(max(u, v))) + 1)
        for pb in range(m0 >> PATCH_BITS, (m1 >> PATCH_BITS) + 1):
            tx = (pb if swap else pa) - tx0
            ty = (pa if swap else pb) - ty0
            if 0 <= tx < tw and 0 <= ty < th and not mark[ty, tx]:
                mark[ty, tx] = True
                out[n] = ty * tw + tx
                n += 1
    return n


@njit(cache=True, nogil=True, parallel=True)
def scan_patches(
    shape, tpx0, tpy0, poses, ranges, cos_a, sin_a, res, usable_range, max_range, todo
):
    """(K, P) table cells (flat, ty * TW + tx) of the patches `_register_one` may write for
    each particle of todo, and (K,) their numbers; on numba's threads (geometry only)."""
    th, tw = shape
    lists = np.empty((todo.shape[0], th * tw), dtype=np.int64)
    counts = np.zeros(todo.shape[0], dtype=np.int64)
    for k in prange(todo.shape[0]):
        p = todo[k]
        mark = np.zeros((th, tw), dtype=np.bool_)
        out = lists[k]
        n = 0
        x, y, theta = poses[p, 0], poses[p, 1], poses[p, 2]
        c, s = np.cos(theta), np.sin(theta)
        x0 = int(np.floor(x / res))
        y0 = int(np.floor(y / res))
        for i in range(ranges.shape[0]):
            d = ranges[i]
            if not (d > 0.0) or d > max_range:
                continue
            _, _, x1, y1 = _beam_end(x, y, c, s, cos_a[i], sin_a[i], min(d, usable_range), res)
            if abs(x1 - x0) >= abs(y1 - y0):
                n = _line_patches(mark, out, n, tpx0, tpy0, x0, y0, x1, y1, False)
            else:
                n = _line_patches(mark, out, n, tpx0, tpy0, y0, x0, y1, x1, True)
        counts[k] = n
    return lists, counts


@njit(cache=True, nogil=True)
def claim_patches(
    visits, hits, mean, bits, counts, free_stack, n_free, tables, lists, n_listed, need, todo,
    start, dirty,
):  # fmt: skip
    """For particles todo[start:] in turn, make writable (copy-on-write, or new) the patches
    `scan_patches` listed, so that the particles can then be registered in parallel
    (`register_claimed`), each writing only patches that are its alone. A claimed patch no
    line touches is a copy or an empty patch: the map reads the same. Returns the next
    position in todo; < len(todo): grow the pool and call again."""
    for k in range(start, todo.shape[0]):
        p = todo[k]
        if n_free[0] < need[p]:
            return k
        table = tables[p]
        tw = table.shape[1]
        for q in range(n_listed[k]):
            ty = lists[k, q] // tw
            tx = lists[k, q] - ty * tw
            e = table[ty, tx]
            if e >= 0 and counts[e] == 1:
                continue
            if (
                _writable_patch(
                    visits, hits, mean, bits, counts, free_stack, n_free, table, tx, ty, dirty
                )
                < 0
            ):
                return k  # cannot happen when need[p] patches were free: they bound the box
    return todo.shape[0]


@njit(cache=True, nogil=True, parallel=True)
def register_claimed(
    visits, hits, mean, bits, counts, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, res,
    usable_range, max_range, todo, dirty,
):  # fmt: skip
    """Register the scan for every particle of todo, in parallel, after `claim_patches`:
    the same cells as `register_scans` would write. Returns the updates dropped (cells off
    the table, or in a patch that was not claimed: 0 when the claim is right)."""
    dropped = np.zeros(todo.shape[0], dtype=np.int64)
    none = np.zeros(0, dtype=np.int32)
    n_free = np.zeros(1, dtype=np.int64)
    for k in prange(todo.shape[0]):
        p = todo[k]
        dropped[k] = _register_one(
            visits, hits, mean, bits, counts, none, n_free, tables[p], tpx0, tpy0, poses[p],
            ranges, cos_a, sin_a, res, usable_range, max_range, dirty, False,
        )  # fmt: skip
    return dropped.sum()
