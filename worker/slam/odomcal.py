"""Online odometry calibration for sparse logs: one scale per axis from the matched steps."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class OdomCalibration:
    """How rbpf estimates its odometry's scale error on a log that kept one scan a metre.

    Each axis (x, y along the robot's frame, theta) gets the least-squares scale s with
    matched_step ~ s * odometry_step over the updates so far, pulled towards 1 by a prior
    worth `prior` of squared motion, and clamped to [1 - limit, 1 + limit].
    """

    prior_m2: float = 4.0  # [m^2] prior weight of scale 1 on x and y (four 1 m steps)
    prior_rad2: float = 4.0  # [rad^2] prior weight of scale 1 on theta
    limit: float = 0.2  # [1] the largest scale error believed (a wheel 20 % off)


class ScaleEstimate:
    """The running per-axis scale of `OdomCalibration`; starts at (1, 1, 1)."""

    def __init__(self, cal: OdomCalibration | None = None):
        self.cal = OdomCalibration() if cal is None else cal
        prior = np.array([self.cal.prior_m2, self.cal.prior_m2, self.cal.prior_rad2])
        self._num = prior.copy()  # prior * 1 + sum matched * odometry
        self._den = prior.copy()  # prior + sum odometry^2
        self.samples = 0

    def add(self, odom_step: np.ndarray, matched_step: np.ndarray) -> None:
        """One update's raw odometry step (3,) and the filter's matched step (3,), both in the
        robot frame of the previous update."""
        o = np.asarray(odom_step, dtype=np.float64)
        m = np.asarray(matched_step, dtype=np.float64)
        self._num += m * o
        self._den += o * o
        self.samples += 1

    @property
    def scale(self) -> np.ndarray:
        """(3,) [1] the current scale of x, y, theta."""
        lim = self.cal.limit
        return np.clip(self._num / self._den, 1.0 - lim, 1.0 + lim)
