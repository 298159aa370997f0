"""The SLAM interface every algorithm implements (`worker.slam.registry.make_slam` makes one by
its name), and the beam geometry they share."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Protocol, runtime_checkable

import numpy as np

from worker.errors import InputError
from worker.slam.grid import OccupancyGrid
from worker.slam.params import SlamParams


class LaserGeometry(Protocol):
    """What SLAM needs of a laser (worker.sim.laser.LaserSpec has these fields)."""

    n_beams: int
    angle_min: float  # [rad] first beam, relative to the robot heading
    angle_increment: float  # [rad]
    range_max: float  # [m] readings at or past this are "no return"


@runtime_checkable
class SlamAlgorithm(Protocol):
    """Online 2D SLAM fed with odometry and laser scans.

    Frames as in ROS: `odom` (the robot's dead reckoning), `map` (the SLAM map; equal to the
    odometry frame at the first scan), and T_map_odom, the correction between the two.

    Optional: `will_read_map(due: bool)`, called by the exploration before `process` with
    whether it reads the map if that scan is an update (an external program then sends the
    map with its estimate: worker.slam.external.client).
    """

    name: str

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        """Feed one scan: t [s], pose_odom (3,) [x, y, theta], ranges_m (B,) [m].

        Returns True when the map / filter was updated with this scan.
        """
        ...

    def pose_estimate(self) -> np.ndarray:
        """(3,) [x, y, theta] map frame: T_map_odom (+) the latest odometry pose."""
        ...

    def T_map_odom(self) -> np.ndarray:
        """(3,) [x, y, theta] the map -> odom correction of the latest update."""
        ...

    def occupancy(self) -> OccupancyGrid:
        """The current map (of the best particle for a particle filter)."""
        ...


def beam_angles(laser: LaserGeometry) -> np.ndarray:
    """(B,) [rad] beam angles relative to the robot heading."""
    n = int(laser.n_beams)
    if n < 1:
        raise InputError(f"laser has {n} beams; at least one is needed")
    return float(laser.angle_min) + float(laser.angle_increment) * np.arange(n, dtype=np.float64)


def beam_limits(laser: LaserGeometry, params: SlamParams) -> tuple[float, float]:
    """(max_range, usable_range) [m] as slam_gmapping sets them: maxRange defaults to the
    laser's maximum minus 1 cm (so no-return readings are ignored), and beams are used up to
    min(maxUrange, maxRange)."""
    max_range = float(laser.range_max) - 0.01 if params.max_range is None else params.max_range
    return max_range, min(params.max_urange, max_range)


@contextmanager
def closed_after(slam: Any) -> Iterator[Any]:
    """`slam`, closed on the way out if it has a `close` (an external program is stopped and
    reaped however the run ends: finished, failed, cancelled or timed out)."""
    try:
        yield slam
    finally:
        close = getattr(slam, "close", None)
        if close is not None:
            close()
