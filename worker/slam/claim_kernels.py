"""Numba kernels of the patch map's parallel scan registration: list the patches each
particle's scan may write (in parallel), claim them and the hit slots its beams' end cells
need (in turn), then write (in parallel). The pools are described in worker.slam.map_kernels.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from worker.slam.map_kernels import (
    PATCH_BITS,
    PATCH_MASK,
    _beam_end,
    _hit_slot,
    _register_one,
    _writable_patch,
)


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
def _claim_hit_slots(
    counts, hslot, hits, mean, bits, hfree, hn_free, table, tpx0, tpy0, pose, ranges, cos_a,
    sin_a, res, usable_range, max_range,
):  # fmt: skip
    """Give a hit slot to every patch of this particle's in which one of its beams ends with a
    hit (the patches were claimed: its alone); False if the hit pool ran out."""
    th, tw = table.shape
    x, y, theta = pose[0], pose[1], pose[2]
    c, s = np.cos(theta), np.sin(theta)
    for i in range(ranges.shape[0]):
        d = ranges[i]
        if not (d > 0.0) or d > max_range or d >= usable_range:
            continue
        _, _, x1, y1 = _beam_end(x, y, c, s, cos_a[i], sin_a[i], d, res)
        tx = (x1 >> PATCH_BITS) - tpx0
        ty = (y1 >> PATCH_BITS) - tpy0
        if 0 <= tx < tw and 0 <= ty < th:
            e = table[ty, tx]
            # a patch claimed is this particle's alone; a slot taken here reads as none
            free = e >= 0 and counts[e] == 1 and hslot[e] < 0
            if free and _hit_slot(hslot, hits, mean, bits, hfree, hn_free, e) < 0:
                return False
    return True


@njit(cache=True, nogil=True)
def claim_patches(
    visits, counts, hslot, free_stack, n_free, hits, mean, bits, hfree, hn_free, tables, lists,
    n_listed, need, todo, start, dirty, tpx0, tpy0, poses, ranges, cos_a, sin_a, res,
    usable_range, max_range,
):  # fmt: skip
    """For particles todo[start:] in turn, make writable (copy-on-write, or new) the patches
    `scan_patches` listed, and give a hit slot to those in which a beam ends with a hit, so
    that the particles can then be registered in parallel (`register_claimed`), each writing
    only patches that are its alone. A claimed patch no line touches is a copy or an empty
    patch: the map reads the same (and a cleared slot reads as none). Returns the next
    position in todo; < len(todo): grow the pools and call again."""
    for k in range(start, todo.shape[0]):
        p = todo[k]
        if n_free[0] < need[p] or hn_free[0] < need[p]:
            return k
        table = tables[p]
        tw = table.shape[1]
        for q in range(n_listed[k]):
            ty = lists[k, q] // tw
            tx = lists[k, q] - ty * tw
            e = table[ty, tx]
            if e >= 0 and counts[e] == 1:
                continue
            e = _writable_patch(
                visits, counts, hslot, free_stack, n_free, hits, mean, bits, hfree, hn_free,
                table, tx, ty, dirty,
            )  # fmt: skip
            if e < 0:
                return k  # cannot happen when need[p] patches were free: they bound the box
        if not _claim_hit_slots(
            counts, hslot, hits, mean, bits, hfree, hn_free, table, tpx0, tpy0, poses[p],
            ranges, cos_a, sin_a, res, usable_range, max_range,
        ):  # fmt: skip
            return k  # nor this: a slot per claimed patch at most, need[p] were free
    return todo.shape[0]


@njit(cache=True, nogil=True, parallel=True)
def register_claimed(
    visits, counts, hslot, hits, mean, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a,
    res, usable_range, max_range, todo, dirty,
):  # fmt: skip
    """Register the scan for every particle of todo, in parallel, after `claim_patches`:
    the same cells as `register_scans` would write. Returns the updates dropped (cells off
    the table, or in a patch or hit slot that was not claimed: 0 when the claim is right)."""
    dropped = np.zeros(todo.shape[0], dtype=np.int64)
    none = np.zeros(0, dtype=np.int32)
    n_free = np.zeros(1, dtype=np.int64)
    for k in prange(todo.shape[0]):
        p = todo[k]
        dropped[k] = _register_one(
            visits, counts, hslot, none, n_free, hits, mean, bits, none, n_free, tables[p],
            tpx0, tpy0, poses[p], ranges, cos_a, sin_a, res, usable_range, max_range, dirty,
            False,
        )  # fmt: skip
    return dropped.sum()
