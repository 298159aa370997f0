"""PatchMaps: the occupancy maps of all particles, sharing 32 x 32-cell patches copy-on-write."""

from __future__ import annotations

import numpy as np

from worker.slam.assembly import MapAssembly, dense_hits
from worker.slam.claim_kernels import claim_patches, register_claimed, scan_patches
from worker.slam.grid import OccupancyGrid
from worker.slam.map_kernels import PATCH, PATCH_BITS, register_scans


class PatchMaps:
    """Per-particle occupancy maps over one pool of patches.

    Cell (gx, gy) covers x in [gx * res, (gx + 1) * res) in the map frame, so every particle
    indexes the same cells; `tables` (N, TH, TW) int32 maps patch (px, py) to a pool id,
    -1 = never seen, with table cell (0, 0) = patch (tpx0, tpy0). The table grows (all
    particles alike) when a scan reaches past it, so a map covers the explored area only.
    Resampling copies table rows, never patches (`select`). The patch pool (`visits`, `hslot`)
    and the hit pool of the patches in which a beam ended (`hits`, `mean`, `bits`) are
    described in worker.slam.map_kernels; the scan matcher reads the latter through
    `match_tables`.
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
        self.counts = np.zeros(0, dtype=np.int32)
        self.hslot = np.zeros(0, dtype=np.int32)  # hit slot of each patch, -1: no hit
        self.hits = np.zeros((0, PATCH, PATCH), dtype=np.float32)
        self.mean = np.zeros((0, PATCH, PATCH, 2), dtype=np.float32)  # [m] in the cell
        self.bits = np.zeros((0, 2, PATCH), dtype=np.int64)  # occupied / full row bit masks
        self._match_tables: np.ndarray | None = None
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

    @property
    def hit_capacity(self) -> int:
        """Hit slots the hit pool holds (used or free)."""
        return self.hits.shape[0]

    def live_patches(self) -> int:
        """Distinct patches referenced by any particle."""
        return int(np.count_nonzero(self.counts))

    def live_hit_slots(self) -> int:
        """Hit slots of the patches referenced by any particle."""
        return int(np.count_nonzero(self.hslot[self.counts > 0] >= 0))

    def nbytes(self) -> int:
        """Bytes held by the pools, the tables and the assembled dense map."""
        planes = self.visits.nbytes + self.hits.nbytes + self.mean.nbytes + self.bits.nbytes
        tables = self.tables.nbytes + self.counts.nbytes + self.hslot.nbytes + self.dirty.nbytes
        return int(planes + tables + self._assembly.nbytes())

    def match_tables(self) -> np.ndarray:
        """(N, TH, TW) int32 every particle's table mapped through `hslot`: the hit slot of the
        patch at each table cell, -1 where none (never seen, or no hit: all bits 0 there). What
        the scan matcher reads `mean` and `bits` through."""
        if self._match_tables is None:
            out = self.hslot[self.tables] if self.hslot.size else np.full_like(self.tables, -1)
            out[self.tables < 0] = -1
            self._match_tables = out
        return self._match_tables

    def select(self, indices: np.ndarray) -> None:
        """Resampling: particle k becomes a copy of old particle indices[k] (shares patches)."""
        self.tables = self.tables[np.asarray(indices, dtype=np.intp)]
        self._match_tables = None
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

    def _grow_pool(self, names: tuple[str, ...], extra: int) -> None:
        """Grow the pool whose planes are `names` by at least `extra` entries (by half)."""
        old = getattr(self, names[0]).shape[0]
        new = max(old + extra, int(old * 1.5), 256)

        # one plane at a time, each old one dropped before the next is copied: the peak is
        # the old pool plus one new plane, not the old pool plus the new one
        for name in names:
            a = getattr(self, name)
            out = np.zeros((new, *a.shape[1:]), dtype=a.dtype)  # new entries are set on use
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
        self._match_tables = None
        if parallel and todo.size > 1:
            self._register_parallel(
                poses, ranges, cos_a, sin_a, usable_range, max_range, need, todo
            )
        else:

            def step(pools: tuple, start: int) -> int:
                start, dropped = register_scans(
                    *pools, self.tables, self.tpx0, self.tpy0, poses, ranges, cos_a, sin_a,
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
        them and their hit slots in turn, then write (in parallel)."""
        lists, n_listed = scan_patches(
            self.tables.shape[1:], self.tpx0, self.tpy0, poses, ranges, cos_a, sin_a,
            self.resolution, usable_range, max_range, todo,
        )  # fmt: skip

        def claim(pools: tuple, start: int) -> int:
            return claim_patches(
                *pools, self.tables, lists, n_listed, need, todo, start, self.dirty, self.tpx0,
                self.tpy0, poses, ranges, cos_a, sin_a, self.resolution, usable_range, max_range,
            )  # fmt: skip

        self._in_pool(need, todo, claim)
        dropped = register_claimed(
            self.visits, self.counts, self.hslot, self.hits, self.mean, self.bits, self.tables,
            self.tpx0, self.tpy0, poses, ranges, cos_a, sin_a, self.resolution, usable_range,
            max_range, todo, self.dirty,
        )  # fmt: skip
        if dropped:  # a patch the claim missed: the maps would differ from the serial ones
            raise RuntimeError(f"parallel scan registration dropped {dropped} cell updates")

    def _in_pool(self, need: np.ndarray, todo: np.ndarray, step) -> None:
        """Run step(pools, start) -> next start over the particles of todo, growing a pool
        whenever its free entries cannot cover the next particle's worst case (need: every
        patch of its scan's bounding box, and a hit slot for each). pools: the kernels'
        (visits, counts, hslot, free patches, their number, hits, mean, bits, free hit slots,
        their number); the free ones are those no particle's table reaches."""
        start = 0
        while start < todo.size:
            worst = int(need[todo[start:]].max())
            # stacks popped from the end: the lowest free ids first, so that entries freed
            # are reused before the untouched capacity is (whose pages are never made
            # resident then)
            free_stack = np.flatnonzero(self.counts == 0)[::-1].astype(np.int32)
            if free_stack.size < need[todo[start]]:
                self._grow_pool(("visits", "counts", "hslot"), worst - free_stack.size)
                continue
            used = np.zeros(self.hit_capacity, dtype=np.bool_)
            slots = self.hslot[self.counts > 0]
            used[slots[slots >= 0]] = True
            hfree = np.flatnonzero(~used)[::-1].astype(np.int32)
            if hfree.size < need[todo[start]]:
                self._grow_pool(("hits", "mean", "bits"), worst - hfree.size)
                continue
            pools = (
                self.visits, self.counts, self.hslot, free_stack,
                np.array([free_stack.size], dtype=np.int64), self.hits, self.mean, self.bits,
                hfree, np.array([hfree.size], dtype=np.int64),
            )  # fmt: skip
            start = step(pools, start)

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

    def _assembled(self, particle: int) -> MapAssembly:
        """The incremental assembly brought up to date with `particle`'s map."""
        a = self._assembly
        a.update(
            self.visits, self.hslot, self.hits, self.tables[particle], self.tpx0, self.tpy0,
            self.dirty,
        )  # fmt: skip
        return a

    def occupancy(self, particle: int, with_hits: bool = False) -> OccupancyGrid:
        """The map of one particle, cropped to its seen cells (a 1 x 1 unknown grid if none);
        with_hits: with its cells' end-point counts (`OccupancyGrid.hits`). Only the patches
        written or re-pointed since the previous call are reassembled (MapAssembly)."""
        a = self._assembled(particle)
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
            hits = dense_hits(self.hslot, self.hits, self.tables[particle])[r0:r1, c0:c1]
        return OccupancyGrid(a.dense[r0:r1, c0:c1], self.resolution, origin, self.occ_thresh, hits)

    def changes(self, particle: int) -> np.ndarray:
        """(K, 4) [x0, y0, x1, y1] map frame [m]: rectangles (whole 32-cell patches) covering
        every cell of `occupancy(particle)` that differs from the map the previous call of
        `changes` saw (at the first call: every seen cell); (0, 4) when none does. The map
        is brought up to date as `occupancy` does (the same incremental assembly)."""
        a = self._assembled(particle)
        rects = a.take_changes()
        side = self.resolution * PATCH
        return (rects + np.array([a.tpx0, a.tpy0, a.tpx0, a.tpy0])) * side


__all__ = ["PatchMaps", "PATCH", "PATCH_BITS"]
