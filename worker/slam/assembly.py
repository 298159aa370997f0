"""One particle's dense map assembled from the patch pool, kept between calls and refreshed only
where patches changed (the laser's footprint since the last call), with the changed patches
remembered for the map feed (`MapAssembly.take_changes`).

A table cell is reassembled when the scan registration marked it dirty (a patch written or
allocated there, `map_kernels._register_one`) or when the particle's pool id there is not the
one it was assembled from (resampling, or another particle asked for). A pool id only ever
appears at one table cell (tables are copied whole, rows aligned), and any change of a patch's
cells marks its cell dirty, so a clean cell with the same id holds the same cells.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from worker.slam.map_kernels import PATCH

NO_BOX = (PATCH, -1, PATCH, -1)  # [row min, row max, col min, col max] of a patch's seen cells


@njit(cache=True, nogil=True)
def refresh_patches(visits, hslot, hits, table, ids, dirty, dense, boxes, changed):
    """Reassemble the table cells (ty, tx) that are dirty or whose pool id differs from ids
    (hits in hit slot hslot[e] of patch e, none where -1: worker.slam.map_kernels).

    dense: (TH*32, TW*32) float32 hits / visits, NaN where never visited (as `dense_prob`);
    boxes: (TH, TW, 4) int32 the seen cells' [row min, row max, col min, col max] in each
    patch (row max -1: none); changed: (TH, TW) bool, set where a reassembled patch's cells
    differ (bit for bit) from what dense held. Returns the number of patches reassembled.
    """
    th, tw = table.shape
    n = 0
    for ty in range(th):
        for tx in range(tw):
            e = table[ty, tx]
            if not dirty[ty, tx] and e == ids[ty, tx]:
                continue
            ids[ty, tx] = e
            n += 1
            r0, c0 = ty * PATCH, tx * PATCH
            rmin, rmax, cmin, cmax = PATCH, -1, PATCH, -1
            differs = False
            s = hslot[e] if e >= 0 else -1
            for ly in range(PATCH):
                for lx in range(PATCH):
                    p = np.float32(np.nan)
                    if e >= 0:
                        v = visits[e, ly, lx]
                        if v > 0:
                            h = hits[s, ly, lx] if s >= 0 else np.float32(0.0)
                            p = np.float32(h / v)
                            rmin, rmax = min(rmin, ly), max(rmax, ly)
                            cmin, cmax = min(cmin, lx), max(cmax, lx)
                    old = dense[r0 + ly, c0 + lx]
                    if p != old and not (np.isnan(p) and np.isnan(old)):
                        differs = True
                        dense[r0 + ly, c0 + lx] = p
            boxes[ty, tx, 0], boxes[ty, tx, 1] = rmin, rmax
            boxes[ty, tx, 2], boxes[ty, tx, 3] = cmin, cmax
            if differs:
                changed[ty, tx] = True
    return n


@njit(cache=True, nogil=True)
def dense_hits(hslot, hits, table):
    """(TH*32, TW*32) float32 end-point counts of one particle's map, 0 where none."""
    th, tw = table.shape
    out = np.zeros((th * PATCH, tw * PATCH), dtype=np.float32)
    for ty in range(th):
        for tx in range(tw):
            e = table[ty, tx]
            if e < 0 or hslot[e] < 0:
                continue
            out[ty * PATCH : (ty + 1) * PATCH, tx * PATCH : (tx + 1) * PATCH] = hits[hslot[e]]
    return out


@njit(cache=True, nogil=True)
def dense_prob(visits, hslot, hits, table):
    """(TH*32, TW*32) float32 hits / visits of one particle's map, NaN where never visited
    (the whole map at once: the reference `refresh_patches` must agree with)."""
    th, tw = table.shape
    out = np.full((th * PATCH, tw * PATCH), np.nan, dtype=np.float32)
    for ty in range(th):
        for tx in range(tw):
            e = table[ty, tx]
            if e < 0:
                continue
            s = hslot[e]
            for ly in range(PATCH):
                for lx in range(PATCH):
                    v = visits[e, ly, lx]
                    if v > 0:
                        h = hits[s, ly, lx] if s >= 0 else np.float32(0.0)
                        out[ty * PATCH + ly, tx * PATCH + lx] = h / v
    return out


class MapAssembly:
    """The dense map of the particle last assembled, over the patch table's extent.

    `update` brings it to a particle's current cells, reassembling only dirty or re-pointed
    patches; `crop` gives the seen cells' bounds; `take_changes` the patches whose cells changed
    since its previous call. Table cells are counted from (tpx0, tpy0), as the PatchMaps table.
    """

    def __init__(self) -> None:
        self.tpx0 = 0
        self.tpy0 = 0
        self.ids = np.full((0, 0), -1, dtype=np.int32)  # (TH, TW) pool ids assembled from
        self.dense = np.zeros((0, 0), dtype=np.float32)  # (TH*32, TW*32) hits / visits
        self.boxes = np.zeros((0, 0, 4), dtype=np.int32)  # (TH, TW, 4) seen cells per patch
        self.changed = np.zeros((0, 0), dtype=np.bool_)  # (TH, TW) since take_changes

    def nbytes(self) -> int:
        return int(self.ids.nbytes + self.dense.nbytes + self.boxes.nbytes + self.changed.nbytes)

    def update(self, visits, hslot, hits, table: np.ndarray, tpx0: int, tpy0: int, dirty) -> int:
        """Bring the map to `table`'s particle (TH, TW) pool ids; clears `dirty`. Returns the
        number of patches reassembled."""
        self._follow(table.shape, tpx0, tpy0)
        n = refresh_patches(
            visits, hslot, hits, table, self.ids, dirty, self.dense, self.boxes, self.changed
        )
        dirty[:] = False
        return int(n)

    def _follow(self, shape: tuple[int, int], tpx0: int, tpy0: int) -> None:
        """Re-grid onto a grown table (it only grows), keeping what was assembled."""
        if shape == self.ids.shape and (tpx0, tpy0) == (self.tpx0, self.tpy0):
            return
        oy, ox = self.tpy0 - tpy0, self.tpx0 - tpx0
        if self.ids.size == 0:
            oy = ox = 0
        th, tw = self.ids.shape

        def grown(old: np.ndarray, fill, scale: int = 1) -> np.ndarray:
            new = np.full((shape[0] * scale, shape[1] * scale, *old.shape[2:]), fill, old.dtype)
            y, x = oy * scale, ox * scale
            new[y : y + th * scale, x : x + tw * scale] = old
            return new

        self.ids = grown(self.ids, -1)
        self.dense = grown(self.dense, np.nan, PATCH)
        self.boxes = grown(self.boxes, 0)
        self.boxes[self.ids < 0] = NO_BOX
        self.changed = grown(self.changed, False)
        self.tpx0, self.tpy0 = tpx0, tpy0

    def crop(self) -> tuple[int, int, int, int] | None:
        """(r0, r1, c0, c1) the rows and columns of dense holding every seen cell; None if
        none is."""
        ty, tx = np.nonzero(self.boxes[..., 1] >= 0)
        if ty.size == 0:
            return None
        b = self.boxes[ty, tx]
        rows, cols = ty * PATCH, tx * PATCH
        r0, r1 = int((rows + b[:, 0]).min()), int((rows + b[:, 1]).max()) + 1
        return r0, r1, int((cols + b[:, 2]).min()), int((cols + b[:, 3]).max()) + 1

    def take_changes(self) -> np.ndarray:
        """(K, 4) int [tx0, ty0, tx1, ty1) table-cell rectangles covering the patches whose
        cells changed since the previous call (runs along each table row, a run repeated on
        the rows above merged into one rectangle); clears the record."""
        runs = []
        for ty in np.flatnonzero(self.changed.any(axis=1)):
            edges = np.diff(np.concatenate(([0], self.changed[ty].view(np.int8), [0])))
            starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
            y = int(ty)
            runs += [(int(a), y, int(b), y + 1) for a, b in zip(starts, ends, strict=True)]
        self.changed[:] = False
        merged: list[list[int]] = []
        open_runs: dict[tuple[int, int], list[int]] = {}
        for x0, y0, x1, y1 in runs:
            prev = open_runs.get((x0, x1))
            if prev is not None and prev[3] == y0:
                prev[3] = y1
                continue
            rect = [x0, y0, x1, y1]
            merged.append(rect)
            open_runs[(x0, x1)] = rect
        return np.array(merged, dtype=np.int64).reshape(-1, 4)
