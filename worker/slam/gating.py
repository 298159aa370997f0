"""Scan input checks and GMapping's update gating (linearUpdate, angularUpdate, temporalUpdate)."""

from __future__ import annotations

import math

import numpy as np

from worker.errors import InputError
from worker.evaluate.se2_scalar import wrap


def check_scan(t: float, pose_odom: np.ndarray, ranges_m: np.ndarray, n_beams: int):
    """Validate one scan's inputs; return (t, pose_odom (3,) float64, ranges (B,) float64)."""
    t = float(t)
    if not math.isfinite(t):
        raise InputError(f"scan time must be finite, got {t}")
    pose = np.asarray(pose_odom, dtype=np.float64).reshape(-1)
    if pose.shape != (3,) or not all(math.isfinite(v) for v in pose.tolist()):
        raise InputError(f"odometry pose must be 3 finite numbers [x, y, theta], got {pose_odom}")
    ranges = np.ascontiguousarray(ranges_m, dtype=np.float64).reshape(-1)
    if ranges.shape[0] != n_beams:
        raise InputError(f"scan at t={t} has {ranges.shape[0]} ranges, the laser {n_beams}")
    return t, pose, ranges


class UpdateGate:
    """Decides, scan by scan, whether the map / filter updates (GMapping's processScan).

    Odometry motion is summed between updates (translation and |rotation| of each step);
    an update happens on the first scan, or when the sums reach linear_update or
    angular_update, or when more than temporal_update seconds passed (if >= 0).
    """

    def __init__(self, linear_update: float, angular_update: float, temporal_update: float):
        self.linear_update = linear_update
        self.angular_update = angular_update
        self.temporal_update = temporal_update
        self.linear_m = 0.0
        self.angular_rad = 0.0
        self.last_pose: np.ndarray | None = None
        self.last_update_t: float | None = None
        self.last_t: float | None = None

    def step(self, t: float, pose_odom: np.ndarray, force: bool = False) -> bool:
        """Account for the move to pose_odom at t; True if this scan is an update (always when
        force: a scan of a log that kept one scan a metre, see RbpfSlam.process)."""
        if self.last_t is not None and t < self.last_t:
            raise InputError(f"scan times must not decrease: {t} after {self.last_t}")
        self.last_t = t
        x, y, theta = pose_odom.tolist()  # floats: numpy scalars cost more per operation
        if self.last_pose is not None:
            x0, y0, theta0 = self.last_pose.tolist()
            self.linear_m += math.hypot(x - x0, y - y0)
            self.angular_rad += abs(wrap(theta - theta0))
        self.last_pose = pose_odom.copy()
        update = (
            force
            or self.last_update_t is None
            or self.linear_m >= self.linear_update
            or self.angular_rad >= self.angular_update
            or (self.temporal_update >= 0 and t - self.last_update_t > self.temporal_update)
        )
        if update:
            self.linear_m = 0.0
            self.angular_rad = 0.0
            self.last_update_t = t
        return update
