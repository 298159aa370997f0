"""The closed exploration loop: simulator -> SLAM -> navigation stack -> simulator, with outcome."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from worker.explore.coverage import align_map_to_world, coverage, reachable_free
from worker.explore.navigator import GoalRecord, Navigator
from worker.explore.params import ExploreParams
from worker.explore.stop_rules import SnapshotRule
from worker.status import RunOutcome

__all__ = ["ExploreParams", "ExplorationResult", "ExploreProgress", "explore"]

# completed: "no_frontier" | "map_unchanged"; failed: "collision" | "stuck" | "time_limit" |
# "slam_diverged"
Reason = Literal[
    "no_frontier", "map_unchanged", "collision", "stuck", "time_limit", "slam_diverged"
]


@dataclass(frozen=True)
class ExploreProgress:
    """What `on_progress` receives, every progress_period of simulated time."""

    t: float  # [s] simulated time
    pose_gt: np.ndarray  # (3,) [x, y, theta] world frame
    pose_est: np.ndarray  # (3,) [x, y, theta] SLAM map frame
    coverage: float  # [0, 1] at the last coverage estimate (every snapshot or 10 s)
    goals_reached: int
    status: str  # what the navigation stack is doing
    # For live viewers (all in the SLAM map frame; None when there is none):
    goal_xy: np.ndarray | None = None  # (2,) [m] the current frontier goal
    plan: np.ndarray | None = None  # (K, 2) [m] the global plan being followed
    ranges: np.ndarray | None = None  # (B,) [m] the latest scan, taken at pose_gt
    occupancy: Callable[[], object] | None = None  # the current SLAM map, read on demand


@dataclass(frozen=True)
class ExplorationResult:
    """One exploration run."""

    outcome: RunOutcome
    reason: Reason
    stop_detail: str  # one human-readable line
    t: np.ndarray  # (N,) [s] 10 Hz timestamps
    pose_gt: np.ndarray  # (N, 3) [x, y, theta] world frame, at t
    pose_est: np.ndarray  # (N, 3) [x, y, theta] SLAM map frame, at t
    path_length_m: float  # [m] ground-truth distance travelled
    coverage: float  # [0, 1] reachable free area the final map marks free (aligned)
    collision: tuple[float, float, float, float] | None  # (t, x, y, theta) of the first one
    final_map: object  # worker.slam.grid.OccupancyGrid
    goals: tuple[GoalRecord, ...]
    goals_reached: int  # "reached" or "explored"
    goals_failed: int
    safety_triggers: int
    recoveries: int
    T_world_map: np.ndarray  # (3,) alignment used for the coverage
    nav_wall_s: np.ndarray  # (N,) [s] wall time of the navigation stack per 0.1 s step
    # (N,) [s] its CPU time (this thread): what it costs on one core, whatever else runs
    nav_cpu_s: np.ndarray
    wall_s: float  # [s] wall time of the whole run

    @property
    def completed(self) -> bool:
        return self.outcome == RunOutcome.COMPLETED


class _Recorder:
    """Growable (N, 7) buffer: t, pose_gt, pose_est."""

    def __init__(self):
        self.buf = np.empty((4096, 7))
        self.nav = np.empty(4096)
        self.cpu = np.empty(4096)
        self.n = 0

    def add(self, t, pose_gt, pose_est, nav_s, cpu_s) -> None:
        if self.n == len(self.buf):
            self.buf = np.concatenate([self.buf, np.empty_like(self.buf)])
            self.nav = np.concatenate([self.nav, np.empty_like(self.nav)])
            self.cpu = np.concatenate([self.cpu, np.empty_like(self.cpu)])
        self.buf[self.n, 0] = t
        self.buf[self.n, 1:4] = pose_gt
        self.buf[self.n, 4:7] = pose_est
        self.nav[self.n] = nav_s
        self.cpu[self.n] = cpu_s
        self.n += 1


def _odom_velocity(prev: np.ndarray | None, cur: np.ndarray, dt: float) -> tuple[float, float]:
    """(v, w) from two odometry poses dt apart (what the robot's encoders tell)."""
    if prev is None:
        return 0.0, 0.0
    dx, dy = cur[0] - prev[0], cur[1] - prev[1]
    forward = dx * math.cos(prev[2]) + dy * math.sin(prev[2])
    dth = (cur[2] - prev[2] + math.pi) % (2 * math.pi) - math.pi
    return forward / dt, dth / dt


def _pose_error(T0: np.ndarray, pose_est: np.ndarray, pose_gt: np.ndarray) -> float:
    """[m] distance between the ground truth and the estimate mapped by T0 into the world."""
    c, s = math.cos(T0[2]), math.sin(T0[2])
    x = T0[0] + c * pose_est[0] - s * pose_est[1]
    y = T0[1] + s * pose_est[0] + c * pose_est[1]
    return math.hypot(x - pose_gt[0], y - pose_gt[1])


def explore(
    world,
    sim,
    slam,
    params: ExploreParams | None = None,
    *,
    oracle: bool = False,
    on_progress: Callable[[ExploreProgress], None] | None = None,
) -> ExplorationResult:
    """Run the robot until a stop rule fires; steer by the SLAM map and pose only.

    world: worker.world.World (for the coverage score and outcome checks only); sim: a
    worker.sim.simulator.Simulator at its start; slam: a worker.slam SlamAlgorithm, fresh.
    oracle: feed the ground-truth pose to SLAM instead of odometry (use the "odometry"
    algorithm: perfect map and pose), which separates navigation failures from SLAM failures.
    """
    p = params or ExploreParams()
    wall0 = time.perf_counter()
    laser = sim.params.laser
    dt = sim.params.dt
    nav = Navigator(p, laser.angles, laser.range_max)
    snapshots = SnapshotRule(p.snapshot_period, p.snapshot_mse)
    start = np.asarray(sim.pose_gt, dtype=float)
    start_cell = (
        int(math.floor((start[0] - world.origin[0]) / world.resolution)),
        int(math.floor((start[1] - world.origin[1]) / world.resolution)),
    )
    reach = reachable_free(world.occ, world.resolution, start_cell, p.footprint_half_m)
    rec = _Recorder()
    n_collisions0 = len(sim.collisions)
    T0 = None
    prev_odom = None
    last_map_t = -math.inf
    last_full_t = 0.0
    no_frontier_since: float | None = None
    last_cov = 0.0
    next_progress = 0.0
    moved_ref, moved_t = start[:2].copy(), 0.0
    reason: Reason | None = None
    detail = ""
    status = "planning"
    while reason is None:
        t = sim.t
        pose_gt = sim.pose_gt
        pose_odom = sim.pose_odom
        ranges = sim.scan()
        updated = slam.process(t, pose_gt if oracle else pose_odom, ranges)
        pose_est = np.asarray(slam.pose_estimate(), dtype=float)
        if T0 is None:
            T0 = align_map_to_world(pose_est[None, :], pose_gt[None, :])
        nav_s = cpu_s = 0.0
        if updated and t - last_map_t >= 1.0 / p.global_costmap_rate - 1e-9:
            grid = slam.occupancy()
            full = t - last_full_t >= p.full_map_check_period
            c0, u0 = time.perf_counter(), time.thread_time()
            nav.update_map(grid.prob, grid.resolution, grid.origin, full)
            nav_s += time.perf_counter() - c0
            cpu_s += time.thread_time() - u0
            last_map_t = t
            if full:
                last_full_t = t
        v0, w0 = _odom_velocity(prev_odom, pose_odom, dt)
        prev_odom = pose_odom
        c0, u0 = time.perf_counter(), time.thread_time()
        cmd = nav.step(t, pose_est, v0, w0, ranges)
        nav_s += time.perf_counter() - c0
        cpu_s += time.thread_time() - u0
        status = cmd.status
        rec.add(t, pose_gt, pose_est, nav_s, cpu_s)
        # --- outcome checks: the harness may look at the ground truth, the robot may not ---
        if cmd.status == "no_frontier":
            # for a whole second: a transient gap in the map must not end the run
            if no_frontier_since is None:
                no_frontier_since = t
            elif t - no_frontier_since >= 1.0 - 1e-9:
                reason, detail = "no_frontier", "no reachable frontier left"
        else:
            no_frontier_since = None
        if len(sim.collisions) > n_collisions0:
            c = sim.collisions[n_collisions0]
            reason = "collision"
            detail = f"hit an obstacle at t={c.t:.1f} s, ({c.x:.2f}, {c.y:.2f})"
        elif _pose_error(T0, pose_est, pose_gt) > p.slam_divergence:
            reason = "slam_diverged"
            detail = f"SLAM pose more than {p.slam_divergence:g} m off at t={t:.1f} s"
        elif nav.stats.consecutive_failures >= p.max_goal_failures:
            reason, detail = "stuck", f"{p.max_goal_failures} goals given up in a row"
        if np.hypot(*(pose_gt[:2] - moved_ref)) > 0.5:
            moved_ref, moved_t = pose_gt[:2].copy(), t
        elif reason is None and t - moved_t >= p.stuck_timeout:
            reason, detail = "stuck", f"moved less than 0.5 m in {p.stuck_timeout:g} s"
        if reason is None and snapshots.due(t):
            grid = slam.occupancy()
            if snapshots.check(t, grid.prob, grid.origin, grid.resolution, grid.occ_thresh):
                reason = "map_unchanged"
                detail = (
                    f"map snapshots {p.snapshot_period:g} s apart: MSE {snapshots.last_mse:.2f}"
                )
        if reason is None and t + dt > p.time_limit + 1e-9:
            reason, detail = "time_limit", f"time limit {p.time_limit:g} s reached"
        if on_progress is not None and t >= next_progress - 1e-9:
            next_progress += p.progress_period
            if int(round(t / dt)) % int(round(10.0 / dt)) == 0:
                last_cov = _coverage(world, reach, slam, rec)
            done = sum(g.status in ("reached", "explored") for g in nav.stats.goals)
            goal = None if nav.goal is None else np.asarray(nav.goal.goal_xy, dtype=float)
            live = (goal, nav.path, ranges, slam.occupancy)
            on_progress(ExploreProgress(t, pose_gt, pose_est, last_cov, done, status, *live))
        if reason is None:
            sim.step(cmd.v, cmd.w)
    return _result(world, sim, slam, nav, rec, reach, reason, detail, n_collisions0, wall0)


def _coverage(world, reach, slam, rec: _Recorder) -> float:
    grid = slam.occupancy()
    T = align_map_to_world(rec.buf[: rec.n, 4:7], rec.buf[: rec.n, 1:4])
    return coverage(
        reach, world.resolution, world.origin, grid.prob, grid.resolution, grid.origin,
        grid.occ_thresh, T,
    )  # fmt: skip


def _result(world, sim, slam, nav, rec, reach, reason, detail, n_col0, wall0):
    grid = slam.occupancy()
    pose_gt = rec.buf[: rec.n, 1:4].copy()
    pose_est = rec.buf[: rec.n, 4:7].copy()
    T = align_map_to_world(pose_est, pose_gt)
    cov = coverage(
        reach, world.resolution, world.origin, grid.prob, grid.resolution, grid.origin,
        grid.occ_thresh, T,
    )  # fmt: skip
    col = sim.collisions[n_col0] if len(sim.collisions) > n_col0 else None
    goals = tuple(nav.stats.goals)
    return ExplorationResult(
        outcome=RunOutcome.COMPLETED
        if reason in ("no_frontier", "map_unchanged")
        else RunOutcome.FAILED,
        reason=reason,
        stop_detail=detail,
        t=rec.buf[: rec.n, 0].copy(),
        pose_gt=pose_gt,
        pose_est=pose_est,
        path_length_m=float(np.sum(np.hypot(*np.diff(pose_gt[:, :2], axis=0).T))),
        coverage=float(cov),
        collision=None if col is None else (col.t, col.x, col.y, col.theta),
        final_map=grid,
        goals=goals,
        goals_reached=sum(g.status in ("reached", "explored") for g in goals),
        goals_failed=sum(g.status == "failed" for g in goals),
        safety_triggers=nav.safety.n_triggers,
        recoveries=nav.stats.recoveries,
        T_world_map=T,
        nav_wall_s=rec.nav[: rec.n].copy(),
        nav_cpu_s=rec.cpu[: rec.n].copy(),
        wall_s=time.perf_counter() - wall0,
    )
