"""PatchMaps: the occupancy maps of all particles, sharing 32 x 32-cell patches copy-on-write."""

from __future__ import annotations

import numpy as np

from worker.slam.assembly import MapAssembly, dense_hits
from worker.slam.grid import OccupancyGrid
from worker.slam.map_kernels import (
    PATCH,
    PATCH_BITS,
    claim_patches,
    register_claimed,
    register_scans,
    scan_patches,
)


class PatchMaps:
    """Per-particle occupancy maps over one pool of patches.

    Cell (gx, gy) covers x in [gx * res, (gx + 1) * res) in the map frame, so every particle
    indexes the same cells; `tables` (N, TH, TW) int32 maps patch (px, py) to a pool id,
    -1 = never seen, with table cell (0, 0) = patch (tpx0, tpy0). The table grows (all
    particles alike) when a scan reaches past it, so a map covers the explored area only.
    Resampling copies table rows, never patches (`select`). The pool's cell planes (`visits`,
    `hits`, `mean`) and row bit masks (`bits`) are described in worker.slam.map_kernels.
    `dirty` (TH, TW) marks the table cells whose patches a scan wrote since the dense map was
    last assembled (worker.slam.assembly): `occupancy` and `changes` reassemble those only.
    """

    def __init__(self, n_particles: int, resolution: float, margin_m: float, occ_thresh: float):
        self.resolution = float(resolution)
        self.occ_thresh = float(occ_thresh)
        self._margin_patches = max(1, int(np.ceil(margin_m / (resolution * PATCH))))
        self.tables = np.full((n_particles, 0, 0), -1, dtype=np.int32)
        self.tpx0 = 0
        self.tpy0 = 0
        self.visits = np.zeros((0, PATCH, PATCH), dtype=np.float32)
        self.hits = np.zeros((0, PATCH, PATCH), dtype=np.float32)
        self.mean = np.zeros((0, PATCH, PATCH, 2), dtype=np.float32)  # [m] in the cell
        self.bits = np.zeros((0, 2, PATCH), dtype=np.int64)  # occupied / full row bit masks
        self.counts = np.zeros(0, dtype=np.int32)
        self.dirty = np.zeros((0, 0), dtype=np.bool_)
        self._assembly = MapAssembly()
        self.dropped = 0  # cell updates lost for lack of pool space (always 0 in practice)

    @property
    def n_particles(self) -> int:
        return self.tables.shape[0]

    @property
    def capacity(self) -> int:
        """Patches the pool holds (live or free)."""
        return self.visits.shape[0]

    def live_patches(self) -> int:
        """Distinct patches referenced by any particle."""
        return int(np.count_nonzero(self.counts))

    def nbytes(self) -> int:
        """Bytes held by the pool, the tables and the assembled dense map."""
        planes = self.visits.nbytes + self.hits.nbytes + self.mean.nbytes + self.bits.nbytes
        tables = self.tables.nbytes + self.counts.nbytes + self.dirty.nbytes
        return int(planes + tables + self._assembly.nbytes())

    def select(self, indices: np.ndarray) -> None:
        """Resampling: particle k becomes a copy of old particle indices[k] (shares patches)."""
        self.tables = self.tables[np.asarray(indices, dtype=np.intp)]
        self._recount()

    def _recount(self) -> None:
        flat = self.tables.ravel()
        self.counts = np.bincount(flat[flat >= 0], minlength=self.capacity).astype(np.int32)

    def _ensure_table(self, lo_x: float, lo_y: float, hi_x: float, hi_y: float) -> None:
        """Grow the tables so that the box [lo, hi] (map frame, [m]) lies inside, plus margin."""
        side = self.resolution * PATCH
        plo_x, plo_y = int(np.floor(lo_x / side)), int(np.floor(lo_y / side))
        phi_x, phi_y = int(np.floor(hi_x / side)), int(np.floor(hi_y / side))
        n, th, tw = self.tables.shape
        if th > 0 and (
            plo_x >= self.tpx0
            and plo_y >= self.tpy0
            and phi_x < self.tpx0 + tw
            and phi_y < self.tpy0 + th
        ):
            return
        m = self._margin_patches
        if th == 0:
            nx0, ny0, nx1, ny1 = plo_x - m, plo_y - m, phi_x + m + 1, phi_y + m + 1
        else:
            nx0 = min(self.tpx0, plo_x - m)
            ny0 = min(self.tpy0, plo_y - m)
            nx1 = max(self.tpx0 + tw, phi_x + m + 1)
            ny1 = max(self.tpy0 + th, phi_y + m + 1)
        grown = np.full((n, ny1 - ny0, nx1 - nx0), -1, dtype=np.int32)
        oy, ox = self.tpy0 - ny0, self.tpx0 - nx0
        grown[:, oy : oy + th, ox : ox + tw] = self.tables
        dirty = np.zeros(grown.shape[1:], dtype=np.bool_)
        dirty[oy : oy + th, ox : ox + tw] = self.dirty
        self.tables, self.dirty, self.tpx0, self.tpy0 = grown, dirty, nx0, ny0

    def _grow_pool(self, extra: int) -> None:
        old = self.capacity
        new = max(old + extra, int(old * 1.5), 256)

        # one plane at a time, each old one dropped before the next is copied: the peak is
        # the old pool plus one new plane, not the old pool plus the new one
        for name in ("visits", "hits", "mean", "bits", "counts"):
            a = getattr(self, name)
            out = np.zeros((new, *a.shape[1:]), dtype=a.dtype)  # new patches are set on use
            out[:old] = a
            del a
            setattr(self, name, out)

    def register(
        self,
        poses: np.ndarray,
        ranges_m: np.ndarray,
        cos_a: np.ndarray,
        sin_a: np.ndarray,
        usable_range: float,
        max_range: float,
        same_as: np.ndarray | None = None,
        parallel: bool = False,
    ) -> None:
        """Integrate one scan into every particle's map at its pose.

        poses: (N, 3) [x, y, theta] map frame; ranges_m: (B,); cos_a, sin_a: (B,) of the
        beam angles relative to the robot heading. same_as: (N,) optional; same_as[k] = j
        says that particle k has the same map and pose as particle j (copies made by
        resampling, before the motion model moves them apart), with same_as[j] = j: the scan
        is registered for j only and k then shares j's patches (copy-on-write, as after
        `select`), which gives k the very cells it would have written itself. parallel: the
        patches each particle may write are claimed first, in turn (`claim_patches`), then the
        particles are registered on numba's threads (`register_claimed`); the cells are the
        same, only pool ids and a few claimed patches the lines missed (empty, or copies)
        differ, which no map read sees.
        """
        poses = np.ascontiguousarray(poses, dtype=np.float64).reshape(-1, 3)
        if poses.shape[0] != self.n_particles:
            raise ValueError(f"{poses.shape[0]} poses for {self.n_particles} particle maps")
        n = self.n_particles
        todo = self._todo(poses, same_as)
        ranges = np.ascontiguousarray(ranges_m, dtype=np.float64)
        need = self._reserve(poses, ranges, usable_range, max_range)
        if parallel and todo.size > 1:
            self._register_parallel(
                poses, ranges, cos_a, sin_a, usable_range, max_range, need, todo
            )
        else:

            def step(free_stack: np.ndarray, n_free: np.ndarray, start: int) -> int:
                start, dropped = register_scans(
                    self.visits, self.hits, self.mean, self.bits, self.counts, free_stack, n_free,
                    self.tables, self.tpx0, self.tpy0, poses, ranges, cos_a, sin_a,
                    self.resolution, usable_range, max_range, need, todo, start, self.dirty,
                )  # fmt: skip
                self.dropped += int(dropped)
                return start

            self._in_pool(need, todo, step)
        if todo.size < n:
            self.tables = self.tables[np.asarray(same_as, dtype=np.int64)]
            self._recount()

    def _register_parallel(self, poses, ranges, cos_a, sin_a, usable_range, max_range, need, todo):
        """`register` with parallel=True: list each particle's patches (in parallel), claim
        them in turn, then write (in parallel)."""
        lists, n_listed = scan_patches(
            self.tables.shape[1:], self.tpx0, self.tpy0, poses, ranges, cos_a, sin_a,
            self.resolution, usable_range, max_range, todo,
        )  # fmt: skip

        def claim(free_stack: np.ndarray, n_free: np.ndarray, start: int) -> int:
            return claim_patches(
                self.visits, self.hits, self.mean, self.bits, self.counts, free_stack, n_free,
                self.tables, lists, n_listed, need, todo, start, self.dirty,
            )  # fmt: skip

        self._in_pool(need, todo, claim)
        dropped = register_claimed(
            self.visits, self.hits, self.mean, self.bits, self.counts, self.tables, self.tpx0,
            self.tpy0, poses, ranges, cos_a, sin_a, self.resolution, usable_range, max_range,
            todo, self.dirty,
        )  # fmt: skip
        if dropped:  # a patch the claim missed: the maps would differ from the serial ones
            raise RuntimeError(f"parallel scan registration dropped {dropped} cell updates")

    def _in_pool(self, need: np.ndarray, todo: np.ndarray, step) -> None:
        """Run step(free_stack, n_free, start) -> next start over the particles of todo,
        growing the pool whenever its free patches cannot cover the next one's worst case
        (need: every patch of its scan's bounding box)."""
        start = 0
        while start < todo.size:
            free_stack = np.flatnonzero(self.counts == 0).astype(np.int32)
            if free_stack.size < need[todo[start]]:
                self._grow_pool(int(need[todo[start:]].max()) - free_stack.size)
                continue
            start = step(free_stack, np.array([free_stack.size], dtype=np.int64), start)

    def _todo(self, poses: np.ndarray, same_as: np.ndarray | None) -> np.ndarray:
        """(K,) the particles whose scan is registered: all, or one of each `same_as` group."""
        n = self.n_particles
        if same_as is None:
            return np.arange(n, dtype=np.int64)
        same_as = np.asarray(same_as, dtype=np.int64)
        if (
            same_as.shape != (n,)
            or np.any(same_as[same_as] != same_as)
            or not np.array_equal(poses[same_as], poses)
            or not np.array_equal(self.tables[same_as], self.tables)
        ):
            raise ValueError("same_as must name, for each particle, an identical one")
        return np.flatnonzero(same_as == np.arange(n)).astype(np.int64)

    def _reserve(
        self, poses: np.ndarray, ranges: np.ndarray, usable_range: float, max_range: float
    ) -> np.ndarray:
        """Grow the patch table over the scans' reach; (N,) the patches each particle may
        allocate at worst (every patch of its scan's bounding box)."""
        used = (ranges > 0) & (ranges <= max_range)
        reach = float(min(np.max(ranges[used]), usable_range)) if used.any() else 0.0
        reach += 2 * self.resolution
        lo = poses[:, :2].min(axis=0) - reach
        hi = poses[:, :2].max(axis=0) + reach
        self._ensure_table(lo[0], lo[1], hi[0], hi[1])
        side = self.resolution * PATCH
        span = np.floor((poses[:, :2] + reach) / side) - np.floor((poses[:, :2] - reach) / side) + 1
        need = (span[:, 0] * span[:, 1]).astype(np.int64)
        self._recount()
        return need

    def occupancy(self, particle: int, with_hits: bool = False) -> OccupancyGrid:
        """The map of one particle, cropped to its seen cells (a 1 x 1 unknown grid if none);
        with_hits: with its cells' end-point counts (`OccupancyGrid.hits`). Only the patches
        written or re-pointed since the previous call are reassembled (MapAssembly)."""
        a = self._assembly
        a.update(self.visits, self.hits, self.tables[particle], self.tpx0, self.tpy0, self.dirty)
        side = self.resolution * PATCH
        origin = np.array([self.tpx0 * side, self.tpy0 * side])
        crop = a.crop()
        if crop is None:
            empty = np.full((1, 1), np.nan, np.float32)
            hits = np.zeros((1, 1), np.float32) if with_hits else None
            return OccupancyGrid(empty, self.resolution, origin, self.occ_thresh, hits)
        r0, r1, c0, c1 = crop
        origin = origin + np.array([c0, r0]) * self.resolution
        hits = None
        if with_hits:
            hits = dense_hits(self.hits, self.tables[particle])[r0:r1, c0:c1]
        return OccupancyGrid(a.dense[r0:r1, c0:c1], self.resolution, origin, self.occ_thresh, hits)

    def changes(self, particle: int) -> np.ndarray:
        """(K, 4) [x0, y0, x1, y1] map frame [m]: rectangles (whole 32-cell patches) covering
        every cell of `occupancy(particle)` that differs from the map the previous call of
        `changes` saw (at the first call: every seen cell); (0, 4) when none does. The map
        is brought up to date as `occupancy` does (the same incremental assembly)."""
        a = self._assembly
        a.update(self.visits, self.hits, self.tables[particle], self.tpx0, self.tpy0, self.dirty)
        rects = a.take_changes()
        side = self.resolution * PATCH
        return (rects + np.array([a.tpx0, a.tpy0, a.tpx0, a.tpy0])) * side


__all__ = ["PatchMaps", "PATCH", "PATCH_BITS"]
