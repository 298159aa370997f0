"""The graph SLAM's occupancy map: scans registered at the nodes' poses, incrementally while
the poses stay, rebuilt from scratch when an optimisation moved them."""

from __future__ import annotations

import math

import numpy as np

from worker.slam.graph.map_kernels import hit_ratio, register_scans
from worker.slam.grid import OccupancyGrid


class NodeMap:
    """Dense hit / visit counts of the nodes registered so far, grown as needed."""

    def __init__(
        self,
        res: float,
        margin: float,
        occ_thresh: float,
        cos_a: np.ndarray,
        sin_a: np.ndarray,
        usable: float,
        max_range: float,
        tolerance: tuple[float, float] = (0.0, 0.0),
    ):
        """tolerance: (xy [m], theta [rad]) a registered node may have moved by before the
        map is rebuilt (0, 0: any move rebuilds it)."""
        self.res, self.margin, self.occ_thresh = res, margin, occ_thresh
        self.tolerance = tolerance
        self._cos_a, self._sin_a = cos_a, sin_a
        self._usable, self._max_range = usable, max_range
        self._hits = np.zeros((0, 0), dtype=np.float32)
        self._visits = np.zeros((0, 0), dtype=np.float32)
        self._ix0 = self._iy0 = 0
        self._poses = np.zeros((0, 3))  # the poses the counts were made with
        self.rebuilds = 0

    def _covers(self, lo: np.ndarray, hi: np.ndarray) -> bool:
        h, w = self._hits.shape
        ilo = np.floor(lo / self.res)
        ihi = np.floor(hi / self.res)
        return bool(
            ilo[0] >= self._ix0
            and ilo[1] >= self._iy0
            and ihi[0] < self._ix0 + w
            and ihi[1] < self._iy0 + h
        )

    def _allocate(self, lo: np.ndarray, hi: np.ndarray) -> None:
        ilo = np.floor((lo - self.margin) / self.res).astype(np.int64)
        ihi = np.floor((hi + self.margin) / self.res).astype(np.int64)
        self._ix0, self._iy0 = int(ilo[0]), int(ilo[1])
        w, h = int(ihi[0] - ilo[0] + 1), int(ihi[1] - ilo[1] + 1)
        self._hits = np.zeros((h, w), dtype=np.float32)
        self._visits = np.zeros((h, w), dtype=np.float32)
        self._poses = np.zeros((0, 3))

    def update(self, poses: np.ndarray, ranges: np.ndarray, reach: np.ndarray) -> None:
        """Bring the counts to the scans ranges (N, B) at poses (N, 3); reach (N,) [m] is how
        far each scan's cells lie from its pose. The first nodes registered before must be the
        same nodes: if any of them moved past the tolerance since it was registered,
        everything is registered again at the current poses."""
        n_done = self._poses.shape[0]
        moved = n_done > 0 and self._moved(poses[:n_done])
        lo = (poses[:, :2] - reach[:, None]).min(axis=0)
        hi = (poses[:, :2] + reach[:, None]).max(axis=0)
        if moved or not self._covers(lo, hi):
            self._allocate(lo, hi)
            self.rebuilds += 1
            n_done = 0
        if n_done == poses.shape[0]:
            return
        register_scans(
            self._hits,
            self._visits,
            self._ix0,
            self._iy0,
            self.res,
            np.ascontiguousarray(poses[n_done:]),
            np.ascontiguousarray(ranges[n_done:]),
            self._cos_a,
            self._sin_a,
            self._usable,
            self._max_range,
        )
        self._poses = np.concatenate([self._poses[:n_done], poses[n_done:]])

    def _moved(self, poses: np.ndarray) -> bool:
        d = poses - self._poses
        dth = np.abs((d[:, 2] + np.pi) % (2 * np.pi) - np.pi)
        tol_xy, tol_th = self.tolerance
        return bool((np.hypot(d[:, 0], d[:, 1]) > tol_xy).any() or (dth > tol_th).any())

    @property
    def registered_poses(self) -> np.ndarray:
        """(N, 3) the poses the counts were made with."""
        return self._poses.copy()

    def occupancy(self, with_hits: bool = False) -> OccupancyGrid:
        """The map as hit / visit ratios (NaN = never seen); with_hits: with its cells'
        end-point counts (`OccupancyGrid.hits`)."""
        if self._hits.size == 0:
            prob = np.full((1, 1), np.nan, dtype=np.float32)
            hits = np.zeros((1, 1), dtype=np.float32)
        else:
            prob = hit_ratio(self._hits, self._visits)
            hits = self._hits
        origin = np.array([self._ix0, self._iy0], dtype=np.float64) * self.res
        return OccupancyGrid(prob, self.res, origin, self.occ_thresh, hits if with_hits else None)

    @property
    def nbytes(self) -> int:
        """Bytes held by the counts."""
        return int(self._hits.nbytes + self._visits.nbytes)


def scan_reach(ranges: np.ndarray, usable: float, max_range: float) -> float:
    """[m] the farthest cell a scan registers (its longest used beam, cut to usable)."""
    ok = (ranges > 0) & (ranges <= max_range)
    return float(min(usable, ranges[ok].max())) + 1e-6 if ok.any() else 0.0 + math.ulp(1.0)
