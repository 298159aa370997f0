"""Laser scanner geometry (Hokuyo UTM-30LX by default): beam count, angles, range."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LaserSpec:
    """A planar laser scanner at the robot's centre, beam 0 at `angle_min` (counter-clockwise).

    Defaults are the Hokuyo UTM-30LX of the thesis: 541 beams over 270 degrees, 0.5 degree apart.
    """

    n_beams: int = 541
    angle_min: float = -3.0 * math.pi / 4.0  # [rad] first beam, relative to the robot heading
    angle_increment: float = math.pi / 360.0  # [rad] between consecutive beams
    range_max: float = 30.0  # [m] readings beyond are reported as range_max
    range_min: float = 0.0  # [m]

    def __post_init__(self) -> None:
        if self.n_beams < 1:
            raise ValueError(f"LaserSpec.n_beams must be >= 1, got {self.n_beams}")
        if not self.range_max > 0.0:
            raise ValueError(f"LaserSpec.range_max must be > 0, got {self.range_max}")

    @property
    def angles(self) -> np.ndarray:
        """Beam angles relative to the robot heading, `(n_beams,)` float64 [rad]."""
        return self.angle_min + self.angle_increment * np.arange(self.n_beams, dtype=np.float64)

    @property
    def angle_max(self) -> float:
        """Angle of the last beam [rad]."""
        return self.angle_min + self.angle_increment * (self.n_beams - 1)

    @property
    def fov(self) -> float:
        """Field of view from the first to the last beam [rad]."""
        return self.angle_increment * (self.n_beams - 1)
