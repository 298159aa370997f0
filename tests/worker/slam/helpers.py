"""Test helpers: hand-derived laser scans in a rectangular room (closed-form ray-box exit)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Laser:
    """Laser geometry with the fields SLAM reads (as worker.sim.laser.LaserSpec)."""

    n_beams: int = 541
    angle_min: float = -3 * math.pi / 4
    angle_increment: float = math.pi / 360
    range_max: float = 30.0

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(self.n_beams)


def box_scan(pose, angles, box=(0.0, 0.0, 8.0, 5.0), range_max=30.0) -> np.ndarray:
    """Ranges (B,) from pose (inside) to the walls of the axis-aligned box (x0, y0, x1, y1)."""
    x, y, th = pose
    x0, y0, x1, y1 = box
    phi = th + np.asarray(angles)
    c, s = np.cos(phi), np.sin(phi)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (x1 - x) / c, np.where(c < 0, (x0 - x) / c, np.inf))
        ty = np.where(s > 0, (y1 - y) / s, np.where(s < 0, (y0 - y) / s, np.inf))
    return np.minimum(np.minimum(tx, ty), range_max)
