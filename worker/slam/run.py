"""Run a SLAM algorithm over a recorded laser log: the core of `mapqual slam`."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory
from worker.slam.base import LaserGeometry, closed_after
from worker.slam.grid import OccupancyGrid
from worker.slam.params import SlamParams, with_defaults_for
from worker.slam.registry import SlamName, make_slam


@dataclass(frozen=True, eq=False)
class SlamRunResult:
    """What a SLAM run over a log gives.

    trajectory: the estimate (map frame) at every laser timestamp, (N,) t and (N, 3) poses:
        the online one, or an algorithm's final one when it has one (graph SLAM's
        `final_trajectory`, after every loop closure; rbpf's, along its best particle).
    online: the estimate each scan had when it was processed (the same object as trajectory
        for an algorithm without a final one).
    grid: the final map. updates: filter updates; wall_s [s]: processing time;
    log_duration_s [s]: the log's span of simulated (or recorded) time.
    """

    algorithm: str
    params: SlamParams
    trajectory: Trajectory
    online: Trajectory
    grid: OccupancyGrid
    updates: int
    wall_s: float
    log_duration_s: float

    @property
    def real_time_factor(self) -> float:
        """Log time per wall-clock time (inf for an instant run)."""
        return self.log_duration_s / self.wall_s if self.wall_s > 0 else float("inf")


def run_slam(
    t: np.ndarray,
    pose_odom: np.ndarray,
    ranges: np.ndarray,
    laser: LaserGeometry,
    algorithm: SlamName = "rbpf",
    params: SlamParams | None = None,
    rng: np.random.Generator | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> SlamRunResult:
    """Feed every scan of a log to a fresh SLAM algorithm.

    t: (N,) [s]; pose_odom: (N, 3) [x, y, theta] the odometry at each scan; ranges: (N, B) [m].
    on_progress(done, total) is called about a hundred times.
    """
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    if n == 0:
        raise InputError("the log holds no laser scans")
    pose_odom = np.asarray(pose_odom, dtype=np.float64).reshape(n, 3)
    params = with_defaults_for(SlamParams() if params is None else params, algorithm)
    slam = make_slam(algorithm, laser, params, rng)
    est = np.empty((n, 3))
    updates = 0
    every = max(1, n // 100)
    wall0 = time.perf_counter()
    with closed_after(slam):
        for k in range(n):
            updates += bool(slam.process(t[k], pose_odom[k], ranges[k]))
            est[k] = slam.pose_estimate()
            if on_progress is not None and (k % every == 0 or k == n - 1):
                on_progress(k + 1, n)
        online = Trajectory.from_samples(t, est)
        final = getattr(slam, "final_trajectory", None)
        # graph SLAM: every scan as the final, optimised graph has it; rbpf: along the best
        # particle's path
        trajectory = online if final is None else Trajectory.from_samples(t, final())
        # the map of that trajectory where the algorithm draws one (graph SLAM's final
        # optimisation), else its current map
        grid = getattr(slam, "final_occupancy", slam.occupancy)()
        # an offline program counts its own (it ran once, over the whole log, at the end)
        updates = max(updates, int(getattr(slam, "updates", 0)))
    wall = time.perf_counter() - wall0
    return SlamRunResult(
        algorithm=algorithm,
        params=params,
        trajectory=trajectory,
        online=online,
        grid=grid,
        updates=updates,
        wall_s=wall,
        log_duration_s=float(t[-1] - t[0]),
    )
