"""Compiled passes over map cells for the protocol: the box or the list of cells that changed
between two maps (the twin's patches and cell lists) and the check-and-copy of received cells,
rectangles or lists (mapqual's side).

Each is one pass over the cells with no temporary grid; the numpy forms they replace made two
to four (a comparison mask, its reductions, the validity masks).
"""

from __future__ import annotations

import numpy as np
from numba import njit

BAD_ABOVE_ONE = 1  # a float32 cell above 1 (+inf included), or -inf
BAD_INT8 = 2  # an int8 cell above 100
BAD_INDEX = 3  # a cell index past the end of the map


@njit(cache=True)
def _row_changed(a, b, r, c0, c1):
    """Whether row r of a and b differ within columns [c0, c1): an OR of XORs over the
    whole span, without an early exit, so that the compiler makes it SIMD."""
    acc = np.uint32(0)
    for c in range(c0, c1):
        acc |= a[r, c] ^ b[r, c]
    return acc != 0


@njit(cache=True)
def changed_box(a, b):
    """(r0, r1, c0, c1): the smallest box [r0, r1) x [c0, c1) holding every cell where the
    (H, W) uint32 arrays a and b differ (the bit patterns of float32 maps, so that NaN equals
    NaN); r0 = -1 when none does. The first and last changed rows are found from the ends;
    the rows between are read only outside the columns already in the box."""
    h, w = a.shape
    r0 = -1
    for r in range(h):
        if _row_changed(a, b, r, 0, w):
            r0 = r
            break
    if r0 < 0:
        return -1, -1, -1, -1
    r1 = r0
    for r in range(h - 1, r0, -1):
        if _row_changed(a, b, r, 0, w):
            r1 = r
            break
    c0, c1 = w, 0  # [c0, c1): grows as changed cells are found
    for r in range(r0, r1 + 1):
        if c0 > 0 and _row_changed(a, b, r, 0, c0):  # left of the box: where exactly
            for c in range(0, c0):
                if a[r, c] != b[r, c]:
                    c0 = c
                    break
        if c1 < w and _row_changed(a, b, r, c1, w):  # right of the box
            for c in range(w - 1, c1 - 1, -1):
                if a[r, c] != b[r, c]:
                    c1 = c + 1
                    break
    return r0, r1 + 1, c0, c1


@njit(cache=True)
def copy_float32(raw, out):
    """Write (H, W) float32 `raw` into `out` (the same shape): NaN and negative values as
    unknown (NaN); 0 when all are probabilities, BAD_ABOVE_ONE at the first that is above 1,
    +inf or -inf (out is then partly written)."""
    h, w = raw.shape
    nan = np.float32(np.nan)
    for r in range(h):
        for c in range(w):
            v = raw[r, c]
            if v > 1.0 or v == -np.inf:
                return BAD_ABOVE_ONE
            out[r, c] = nan if v < 0.0 else v
    return 0


@njit(cache=True)
def copy_int8(raw, out):
    """Write (H, W) int8 `raw` (ROS's 0..100 percent, negative unknown) into float32 `out`
    as probabilities; 0, or BAD_INT8 at the first cell above 100."""
    h, w = raw.shape
    nan = np.float32(np.nan)
    hundred = np.float32(100.0)
    for r in range(h):
        for c in range(w):
            v = raw[r, c]
            if v > 100:
                return BAD_INT8
            out[r, c] = nan if v < 0 else np.float32(v) / hundred
    return 0


@njit(cache=True)
def changed_cells(a, b, index_out, row0, col0, width):
    """The cells where the (h, w) uint32 arrays a and b differ (the bit patterns of float32
    maps: NaN equals NaN), in one pass. a and b may be windows of wider maps, at (row0, col0)
    of maps `width` cells wide: the cells' flat indices in the map, (row0 + r) * width + col0
    + c, ascending, are written to `index_out` (uint32, at least h * w long). Returns (n, r0,
    r1, c0, c1): their number and their bounding box [r0, r1) x [c0, c1) in the map (n = 0:
    none, box (-1, -1, -1, -1)). Each row is first compared whole (SIMD, no early exit) and
    read cell by cell only where it changed."""
    h, w = a.shape
    n = 0
    r0, r1, c0, c1 = -1, -1, w, 0
    for r in range(h):
        if not _row_changed(a, b, r, 0, w):
            continue
        if r0 < 0:
            r0 = r
        r1 = r + 1
        base = (row0 + r) * width + col0
        for c in range(w):
            if a[r, c] != b[r, c]:
                index_out[n] = base + c
                n += 1
                if c < c0:
                    c0 = c
                if c + 1 > c1:
                    c1 = c + 1
    if n == 0:
        return 0, -1, -1, -1, -1
    return n, row0 + r0, row0 + r1, col0 + c0, col0 + c1


@njit(cache=True)
def check_cells(raw, is_int8):
    """0 when every cell of the flat `raw` (float32, or int8 when is_int8) is what copy_float32
    / copy_int8 take, else BAD_ABOVE_ONE or BAD_INT8: the check alone, nothing written."""
    for k in range(raw.shape[0]):
        v = raw[k]
        if is_int8:
            if v > 100:
                return BAD_INT8
        elif v > 1.0 or v == -np.inf:
            return BAD_ABOVE_ONE
    return 0


@njit(cache=True)
def scatter(index, raw, out, is_int8):
    """Write `raw` (K,) into the flat float32 `out` at `index` (K,) uint32, as copy_float32
    (float32 cells, NaN and negatives unknown) or copy_int8 (is_int8: ROS's percent, negatives
    unknown) do, or nothing: BAD_INDEX when an index lies past the end, BAD_ABOVE_ONE /
    BAD_INT8 when a value is out of range, else 0 (all written)."""
    size = out.shape[0]
    for k in range(index.shape[0]):
        if index[k] >= size:
            return BAD_INDEX
    bad = check_cells(raw, is_int8)
    if bad:
        return bad
    nan = np.float32(np.nan)
    hundred = np.float32(100.0)
    for k in range(index.shape[0]):
        v = raw[k]
        if v < 0:
            out[index[k]] = nan
        elif is_int8:
            out[index[k]] = np.float32(v) / hundred
        else:
            out[index[k]] = v
    return 0
