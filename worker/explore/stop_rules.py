"""Stop rules of the thesis's exploration script: map snapshots compared by mean squared error."""

from __future__ import annotations

import math

import numpy as np

# map_saver's grey levels: the thesis compared the saved map images pixel by pixel
_OCCUPIED, _FREE, _UNKNOWN = 0, 254, 205


def map_image(prob: np.ndarray, occ_thresh: float) -> np.ndarray:
    """`(H, W) uint8` map_saver levels (0 occupied, 254 free, 205 unknown), bottom row first."""
    img = np.full(prob.shape, _UNKNOWN, dtype=np.uint8)
    known = ~np.isnan(prob)
    img[known] = np.where(prob[known] > occ_thresh, _OCCUPIED, _FREE)
    return img


def snapshot_mse(a: np.ndarray, a_origin, b: np.ndarray, b_origin, resolution: float) -> float:
    """Mean squared pixel difference of two map images placed on their common extent.

    a, b: (H, W) uint8 images (bottom row first) with the world position of their lower-left
    corner; both share `resolution`. The part only one of them covers counts as unknown in
    the other, as a map that grew shows new pixels against the old image's background.
    """
    ax, ay = (int(round(v / resolution)) for v in np.asarray(a_origin)[:2])
    bx, by = (int(round(v / resolution)) for v in np.asarray(b_origin)[:2])
    x0, y0 = min(ax, bx), min(ay, by)
    x1 = max(ax + a.shape[1], bx + b.shape[1])
    y1 = max(ay + a.shape[0], by + b.shape[0])
    ca = np.full((y1 - y0, x1 - x0), _UNKNOWN, dtype=np.float32)
    cb = ca.copy()
    ca[ay - y0 : ay - y0 + a.shape[0], ax - x0 : ax - x0 + a.shape[1]] = a
    cb[by - y0 : by - y0 + b.shape[0], bx - x0 : bx - x0 + b.shape[1]] = b
    return float(np.mean((ca - cb) ** 2))


class SnapshotRule:
    """Takes a map snapshot every `period` s; fires when two consecutive differ by < `mse`."""

    def __init__(self, period: float, mse: float):
        self.period = period
        self.mse = mse
        self.next_t = period
        self._last: tuple[np.ndarray, np.ndarray] | None = None
        self.last_mse = math.nan

    def due(self, t: float) -> bool:
        return t >= self.next_t - 1e-9

    def check(self, t: float, prob: np.ndarray, origin, resolution: float, occ_thresh: float):
        """Take the snapshot due at t; True when it differs from the previous by less than mse."""
        self.next_t += self.period
        img = map_image(prob, occ_thresh)
        origin = np.asarray(origin, dtype=float)[:2].copy()
        last, self._last = self._last, (img, origin)
        if last is None:
            return False
        self.last_mse = snapshot_mse(last[0], last[1], img, origin, resolution)
        return self.last_mse < self.mse
