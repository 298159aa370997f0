"""Numba kernels of the patch map: copy-on-write patches, scan registration.

The map of every particle is a table of patch ids into one shared pool of 32 x 32-cell
patches (GMapping's HierarchicalArray2D, patch magnitude 5). A patch referenced by several
particles is copied before a particle writes into it (GMapping copies the patches of the
active area before registering a scan); `counts` holds the exact reference counts.
Each cell keeps GMapping's PointAccumulator, stored as separate planes so that each pass
touches only what it needs. The patch pool holds `visits` (P, 32, 32) float32 (the only plane
a free cell's update writes) and `hslot` (P,) int32, the patch's slot in the hit pool, -1
while no beam has ended in the patch (about half the patches of a run: those only crossed
by beams). The hit pool holds, per slot, `hits` (H, 32, 32) float32, `mean` (H, 32, 32, 2)
float32, the running mean of the hit points relative to the cell's lower-left corner [m]
(what the scan matcher reads; float32 keeps sub-millimetre precision there), and `bits`
(H, 2, 32) int64, per patch row two bit masks over the row's cells, kept current by every
write: OCCUPIED (hits / visits > 0.1) and FULL (>= 0.1). The scan matcher reads these first
and touches `mean` only for occupied cells. A patch without a slot has no hit, so its bits
would all be 0: the matcher is given the tables mapped through `hslot`
(`PatchMaps.match_tables`), in which such a patch is -1, as a patch never seen.
A slot belongs to one patch; a patch copied on write gets a copy of its slot. Free patches
and free slots are handed out from stacks (`free_stack`, `hfree`, with their sizes `n_free`,
`hn_free` (1,) int64) that the caller fills with what no particle references.
"""

from __future__ import annotations

import numpy as np
from numba import njit

PATCH_BITS = 5
PATCH = 1 << PATCH_BITS  # [cells] patch side
PATCH_MASK = PATCH - 1
OCCUPIED, FULL = 0, 1  # bit-mask planes of `bits`
FULLNESS = 0.1  # GMapping's m_fullnessThreshold on hits / visits


@njit(cache=True, nogil=True, inline="always")
def _pop(stack, n):
    """The top of a free stack (its size in n (1,)); -1 when it is empty."""
    if n[0] == 0:
        return -1
    n[0] -= 1
    return stack[n[0]]


@njit(cache=True, nogil=True)
def _writable_patch(
    visits, counts, hslot, free_stack, n_free, hits, mean, bits, hfree, hn_free, table, tx, ty,
    dirty,
):  # fmt: skip
    """Patch id that this particle may write at table cell (tx, ty); -1 if a pool is full.
    A patch allocated there marks the cell in `dirty` (TH, TW) bool."""
    e = table[ty, tx]
    if e >= 0 and counts[e] == 1:
        return e
    if n_free[0] == 0 or (e >= 0 and hslot[e] >= 0 and hn_free[0] == 0):
        return -1
    new = _pop(free_stack, n_free)
    hslot[new] = -1  # a free patch's old slot was given back with it
    if e < 0:
        visits[new] = 0.0
    else:
        visits[new] = visits[e]  # copy-on-write of a shared patch
        s = hslot[e]
        if s >= 0:
            c = _pop(hfree, hn_free)
            hits[c] = hits[s]
            mean[c] = mean[s]
            bits[c] = bits[s]
            hslot[new] = c
        counts[e] -= 1
    counts[new] = 1
    table[ty, tx] = new
    dirty[ty, tx] = True
    return new


@njit(cache=True, nogil=True)
def _hit_slot(hslot, hits, mean, bits, hfree, hn_free, e):
    """The hit slot of patch e (this particle's alone), a cleared one taken if it has none;
    -1 if the hit pool is empty."""
    s = hslot[e]
    if s >= 0:
        return s
    s = _pop(hfree, hn_free)
    if s >= 0:
        hits[s] = 0.0
        mean[s] = 0.0
        bits[s] = 0
        hslot[e] = s
    return s


@njit(cache=True, nogil=True, inline="always")
def _update_bits(visits, hits, bits, e, s, ly, lx):
    """Refresh the OCCUPIED / FULL bits of cell (ly, lx) of patch e (hit slot s) after a
    write."""
    h = hits[s, ly, lx]
    limit = FULLNESS * visits[e, ly, lx]
    bit = np.int64(1) << lx
    if h > limit:
        bits[s, OCCUPIED, ly] |= bit
    else:
        bits[s, OCCUPIED, ly] &= ~bit
    if h >= limit and h > 0:
        bits[s, FULL, ly] |= bit
    else:
        bits[s, FULL, ly] &= ~bit


@njit(cache=True, nogil=True, inline="always")
def _beam_end(x, y, c, s, cos_ai, sin_ai, d, res):
    """(hx, hy, x1, y1): the end point [m] of a beam of length d from (x, y) with heading
    cos / sin (c, s) and beam angle cos / sin (cos_ai, sin_ai), and its cell."""
    hx = x + d * (c * cos_ai - s * sin_ai)
    hy = y + d * (s * cos_ai + c * sin_ai)
    return hx, hy, int(np.floor(hx / res)), int(np.floor(hy / res))


@njit(cache=True, nogil=True)
def _register_one(
    visits, counts, hslot, free_stack, n_free, hits, mean, bits, hfree, hn_free, table, tpx0,
    tpy0, pose, ranges, cos_a, sin_a, res, usable_range, max_range, dirty, may_allocate=True,
):  # fmt: skip
    """Integrate one scan into one particle's map (GMapping ScanMatcher::registerScan).

    Beams longer than max_range (or 0 / NaN) are ignored; beams longer than usable_range are
    cut to it and mark free cells only. Cells on the Bresenham line before the end cell get
    one visit; the end cell, for a beam shorter than usable_range, a hit at the end point.
    The Bresenham steps are branch-free (selects), the patch is looked up only when the line
    leaves one. Returns the number of cell updates dropped for lack of pool space (0 when
    the caller reserved enough patches and slots). may_allocate False (the patches and the
    hit slots were claimed beforehand, `claim_kernels.claim_patches`; particles registered in
    parallel): a patch not this particle's alone, or a hit in a patch without a slot, is not
    written, and its updates count as dropped. Every table cell whose patch is written is
    marked in `dirty` (TH, TW) bool (the incremental map assembly's cue).
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
        last_tx, last_ty, e, slot = -(1 << 30), -(1 << 30), -1, -1
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
                                visits, counts, hslot, free_stack, n_free, hits, mean, bits,
                                hfree, hn_free, table, tx, ty, dirty,
                            )  # fmt: skip
                        else:
                            e = -1
                    if e >= 0:
                        dirty[ty, tx] = True
                        slot = hslot[e]
            if at_end and e >= 0 and slot < 0:
                slot = -1
                if may_allocate:
                    slot = _hit_slot(hslot, hits, mean, bits, hfree, hn_free, e)
                if slot < 0:
                    e = -1
            if e < 0:
                dropped += 1
            else:
                # unsigned indices: numba then skips its negative-index wraparound
                ue = np.uintp(e)
                ly = np.uintp(cy & PATCH_MASK)
                lx = np.uintp(cx & PATCH_MASK)
                visits[ue, ly, lx] += 1.0
                if at_end:
                    us = np.uintp(slot)
                    h = hits[us, ly, lx] + 1.0
                    hits[us, ly, lx] = h
                    # running mean of the hit points (GMapping keeps their sum)
                    mean[us, ly, lx, 0] += (hx - cx * res - mean[us, ly, lx, 0]) / h
                    mean[us, ly, lx, 1] += (hy - cy * res - mean[us, ly, lx, 1]) / h
                    _update_bits(visits, hits, bits, ue, us, ly, lx)
                elif slot >= 0 and (bits[np.uintp(slot), FULL, ly] >> lx) & 1:
                    # a visit alone can only clear bits, and only of a cell that has them
                    _update_bits(visits, hits, bits, ue, np.uintp(slot), ly, lx)
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
    visits, counts, hslot, free_stack, n_free, hits, mean, bits, hfree, hn_free, tables, tpx0,
    tpy0, poses, ranges, cos_a, sin_a, res, usable_range, max_range, need, todo, start, dirty,
):  # fmt: skip
    """Register the scan for particles todo[start:] in turn; stop early when a pool runs
    short.

    need: (N,) patches (and hit slots) a particle may have to allocate (its scan's bounding
    box). Returns (next position in todo, dropped cell updates); next < len(todo) means: grow
    the pools and call again.
    """
    dropped = 0
    for k in range(start, todo.shape[0]):
        p = todo[k]
        if n_free[0] < need[p] or hn_free[0] < need[p]:
            return k, dropped
        dropped += _register_one(
            visits, counts, hslot, free_stack, n_free, hits, mean, bits, hfree, hn_free,
            tables[p], tpx0, tpy0, poses[p], ranges, cos_a, sin_a, res, usable_range, max_range,
            dirty,
        )  # fmt: skip
    return todo.shape[0], dropped
