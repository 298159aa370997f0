"""The dead-reckoning baseline: maps with the raw odometry, no correction (T_map_odom = 0)."""

from __future__ import annotations

import numpy as np

from worker.slam.base import LaserGeometry, beam_angles, beam_limits
from worker.slam.gating import UpdateGate, check_scan
from worker.slam.grid import OccupancyGrid
from worker.slam.params import SlamParams
from worker.slam.patchmap import PatchMaps


class OdometrySlam:
    """Registers each update's scan at the odometry pose, with GMapping's map and gating.

    Fed ground-truth poses instead of odometry it builds the perfect map ("oracle" mode).
    With linear_update = angular_update = 0 every scan is an update.
    """

    name = "odometry"

    def __init__(self, laser: LaserGeometry, params: SlamParams):
        self.params = params
        angles = beam_angles(laser)
        self._n_beams = angles.shape[0]
        self._cos_a, self._sin_a = np.cos(angles), np.sin(angles)
        self._max_range, self._usable = beam_limits(laser, params)
        self._gate = UpdateGate(params.linear_update, params.angular_update, params.temporal_update)
        self.maps = PatchMaps(1, params.delta, params.map_margin, params.occ_thresh)
        self._pose_odom = np.zeros(3)
        self.updates = 0
        self._grid: OccupancyGrid | None = None  # cached map of the latest update

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        t, pose, ranges = check_scan(t, pose_odom, ranges_m, self._n_beams)
        self._pose_odom = pose
        if not self._gate.step(t, pose):
            return False
        self.maps.register(
            pose[None, :], ranges, self._cos_a, self._sin_a, self._usable, self._max_range
        )
        self.updates += 1
        self._grid = None
        return True

    def pose_estimate(self) -> np.ndarray:
        return self._pose_odom.copy()

    def T_map_odom(self) -> np.ndarray:
        return np.zeros(3)

    def occupancy(self) -> OccupancyGrid:
        # the grid is immutable: rebuild it only after an update changed the maps
        if self._grid is None:
            self._grid = self.maps.occupancy(0)
        return self._grid

    def occupancy_with_hits(self) -> OccupancyGrid:
        """`occupancy` with its cells' end-point counts (for the map score; not cached)."""
        return self.maps.occupancy(0, with_hits=True)

    def map_changes(self) -> np.ndarray:
        """(K, 4) [x0, y0, x1, y1] map frame [m]: where the map changed since the previous
        call (see RbpfSlam.map_changes)."""
        return self.maps.changes(0)
