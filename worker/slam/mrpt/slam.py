"""MRPT's rbpf-slam and icp-slam as offline SLAM algorithms (replay only): the scans are
collected, written as an action / sensory-frame rawlog, the program runs once over it, and its
path becomes the final trajectory, in mapqual's map frame (the odometry frame at the first
scan) and at the scans' exact time stamps."""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from worker.errors import InputError
from worker.evaluate.se2 import compose
from worker.slam.base import LaserGeometry, beam_angles
from worker.slam.gating import check_scan
from worker.slam.grid import OccupancyGrid
from worker.slam.mrpt.programs import MrptProgram, read_path, run_program
from worker.slam.mrpt.rawlog import write_rawlog
from worker.slam.odometry import OdometrySlam
from worker.slam.params import SlamParams

# [s] the program's wall-time limit per scan (FR079's 4,933 scans: about 80 min at most)
TIMEOUT_PER_SCAN_S = 1.0
TIMEOUT_MIN_S = 120.0


class MrptSlam:
    """An MRPT program behind the SlamAlgorithm interface, offline: while scans come in the
    estimate is the odometry (no correction); `final_trajectory` runs the program over all of
    them and `final_occupancy` draws mapqual's map along its path."""

    def __init__(self, prog: MrptProgram, laser: LaserGeometry, params: SlamParams,
                 rng: np.random.Generator):  # fmt: skip
        prog.which()  # refuses at once, in one line, when MRPT is not installed
        prog.config_path()
        self.name = prog.name
        self.prog = prog
        self.params = params
        self.laser = laser
        self._n_beams = beam_angles(laser).shape[0]
        self._seed = int(rng.integers(1, 2**31 - 1))
        self._t: list[float] = []
        self._odom: list[np.ndarray] = []
        self._ranges: list[np.ndarray] = []
        self._path: np.ndarray | None = None
        self._grid: OccupancyGrid | None = None
        self._final_grid: OccupancyGrid | None = None
        self.updates = 0

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        t, pose, ranges = check_scan(t, pose_odom, ranges_m, self._n_beams)
        if self._t and not t > self._t[-1]:
            raise InputError(
                f"{self.name}: scan time stamps must increase ({t} after {self._t[-1]})"
            )
        self._t.append(t)
        self._odom.append(pose)
        self._ranges.append(np.asarray(ranges, dtype=float))
        self._path = None
        return False

    def pose_estimate(self) -> np.ndarray:
        return self._odom[-1].copy() if self._odom else np.zeros(3)

    def T_map_odom(self) -> np.ndarray:
        return np.zeros(3)

    def occupancy(self) -> OccupancyGrid:
        if self._grid is None:
            self._grid = self._draw(np.asarray(self._odom).reshape(-1, 3))
        return self._grid

    def final_trajectory(self) -> np.ndarray:
        """(N, 3) the program's path at every scan, in the map frame."""
        if self._path is None:
            self._path = self._run()
            self._final_grid = None
        return self._path

    def final_occupancy(self) -> OccupancyGrid:
        """mapqual's map of the scans registered along the program's path."""
        if self._final_grid is None:
            self._final_grid = self._draw(self.final_trajectory())
        return self._final_grid

    def _run(self) -> np.ndarray:
        t = np.asarray(self._t)
        odom = np.asarray(self._odom).reshape(-1, 3)
        if t.shape[0] == 0:
            raise InputError(f"{self.name}: no scans")
        timeout = max(TIMEOUT_MIN_S, TIMEOUT_PER_SCAN_S * t.shape[0])
        with tempfile.TemporaryDirectory(prefix="mapqual-mrpt-") as tmp:
            work = Path(tmp)
            rawlog = work / "log.rawlog"
            lz = self.laser
            write_rawlog(rawlog, t, odom, np.asarray(self._ranges), float(lz.angle_min),
                         float(lz.angle_increment), float(lz.range_max))  # fmt: skip
            out = run_program(self.prog, rawlog, work, self._seed, timeout)
            own = read_path(self.prog, out, t)
        self.updates = int(t.shape[0])
        # the program starts at its origin: mapqual's map frame is the first odometry pose's
        return np.array([compose(odom[0], p) for p in own])

    def _draw(self, poses: np.ndarray) -> OccupancyGrid:
        """The map of the scans at `poses`, with the odometry baseline's gating and map."""
        draw = OdometrySlam(self.laser, self.params)
        for k in range(poses.shape[0]):
            draw.process(self._t[k], poses[k], self._ranges[k])
        return draw.occupancy()


def rbpf_factory(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> MrptSlam:
    from worker.slam.mrpt.programs import RBPF

    return MrptSlam(RBPF, laser, params, rng)


def icp_factory(laser: LaserGeometry, params: SlamParams, rng: np.random.Generator) -> MrptSlam:
    from worker.slam.mrpt.programs import ICP

    return MrptSlam(ICP, laser, params, rng)
