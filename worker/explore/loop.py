"""The closed exploration loop: simulator -> SLAM -> navigation stack -> simulator, with outcome."""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from worker.errors import SlamFailed
from worker.evaluate import se2
from worker.evaluate.coverage import (
    ReachCells,
    align_map_to_world,
    reachable_free,
    seen_free,
    unseen_regions,
)
from worker.explore.navigator import GoalRecord, Navigator
from worker.explore.params import ExploreParams
from worker.explore.stop_rules import (
    LoopState,
    Outcome,
    Reason,
    StopReason,
    default_rules,
    first_stop,
)
from worker.heap import release_free_heap
from worker.status import RunOutcome

__all__ = [
    "Exploration", "ExploreParams", "ExplorationResult", "ExploreProgress", "Outcome", "Reason",
    "explore", "judge_outcome",
]  # fmt: skip


@dataclass(frozen=True)
class ExploreProgress:
    """What `on_progress` receives, every progress_period of simulated time."""

    t: float  # [s] simulated time
    pose_gt: np.ndarray  # (3,) [x, y, theta] world frame
    pose_est: np.ndarray  # (3,) [x, y, theta] SLAM map frame
    coverage: float  # [0, 1] at the last coverage estimate (every coverage_period)
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
    # (N, 3) [x, y, theta] SLAM map frame, at t: the algorithm's final trajectory where it
    # keeps one (rbpf: the best particle's path at the end, the one the final map was drawn
    # along; graph: the final optimised graph), None where it does not (odometry, external
    # programs). pose_est is the online estimate the robot drove on.
    pose_final: np.ndarray | None = None

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


class Exploration:
    """One closed-loop exploration, one control period per `step` (what `explore` runs)."""

    def __init__(self, world, sim, slam, p: ExploreParams, oracle: bool, on_progress):
        self.wall0 = time.perf_counter()
        self.world, self.sim, self.slam, self.p = world, sim, slam, p
        self.oracle = oracle
        self.on_progress = on_progress
        laser = sim.params.laser
        self.dt = sim.params.dt
        self.nav = Navigator(p, laser.angles, laser.range_max, sim.params.laser_noise_sigma)
        start = np.asarray(sim.pose_gt, dtype=float)
        start_cell = (
            int(math.floor((start[0] - world.origin[0]) / world.resolution)),
            int(math.floor((start[1] - world.origin[1]) / world.resolution)),
        )
        half = p.costmap.footprint_half_m
        self.reach = reachable_free(world.occ, world.resolution, start_cell, half)
        # the part behind gaps the robot can drive through: what `incomplete` is judged on
        self.passable = reachable_free(
            world.occ, world.resolution, start_cell, half, p.passable_clearance_m
        )
        self.rec = _Recorder()
        self.n_collisions0 = len(sim.collisions)
        self.rules = default_rules(p.stop, p.time_limit, start, self.n_collisions0)
        self.prev_odom: np.ndarray | None = None
        self.last_map_t = -math.inf  # [s] the last costmap update
        # an algorithm that can send its map with the update it is read after (an external
        # program: one round trip, not two) is told beforehand when that will be
        self.map_hint = getattr(slam, "will_read_map", None)
        self.last_full_t = 0.0  # [s] the last whole-map re-read
        self.last_cov = 0.0
        self.reach_cells: ReachCells | None = None  # for the live coverage (on_progress)
        self.next_progress = 0.0  # [s]

    def step(self) -> StopReason | None:
        """Sense, map, navigate, check the stop rules, report; drive on unless one fired."""
        sim, slam = self.sim, self.slam
        t = sim.t
        pose_gt = sim.pose_gt
        pose_odom = sim.pose_odom
        ranges = sim.scan()
        if self.map_hint is not None:  # whether _feed_map reads the map if this scan updates it
            self.map_hint(self._map_due(t))
        try:
            updated = slam.process(t, pose_gt if self.oracle else pose_odom, ranges)
        except SlamFailed as exc:  # an external program crashed, stalled or broke the protocol
            return self._slam_failed(t, pose_gt, pose_odom, exc)
        pose_est = np.asarray(slam.pose_estimate(), dtype=float)
        nav_s, cpu_s = self._feed_map(t, updated)
        v0, w0 = _odom_velocity(self.prev_odom, pose_odom, self.dt)
        self.prev_odom = pose_odom
        c0, u0 = time.perf_counter(), time.thread_time()
        cmd = self.nav.step(t, pose_est, v0, w0, ranges)
        nav_s += time.perf_counter() - c0
        cpu_s += time.thread_time() - u0
        self.rec.add(t, pose_gt, pose_est, nav_s, cpu_s)
        failures = self.nav.stats.consecutive_failures
        goal = self.nav.pursuit
        state = LoopState(
            t, self.dt, pose_gt, pose_est, cmd.status, failures, sim.collisions, slam.occupancy,
            None if goal is None else goal.t0,
        )  # fmt: skip
        stop = first_stop(self.rules, state)
        if self.on_progress is not None and t >= self.next_progress - 1e-9:
            self._progress(t, pose_gt, pose_est, cmd.status, ranges)
        if stop is None:
            sim.step(cmd.v, cmd.w)
        return stop

    def _slam_failed(self, t: float, pose_gt, pose_odom, exc: SlamFailed) -> StopReason:
        """failed, slam_failed: this step recorded with the last estimate (the odometry at the
        first step, where the map frame is the odometry frame), the robot stopped."""
        rec = self.rec
        pose_est = rec.buf[rec.n - 1, 4:7].copy() if rec.n else np.asarray(pose_odom, dtype=float)
        rec.add(t, pose_gt, pose_est, 0.0, 0.0)
        return StopReason("slam_failed", str(exc))

    def _map_due(self, t: float) -> bool:
        """Whether the costmap takes the SLAM map at `t` if the SLAM updated it (at
        global_costmap_rate)."""
        return t - self.last_map_t >= 1.0 / self.p.costmap.global_costmap_rate - 1e-9

    def _feed_map(self, t: float, updated: bool) -> tuple[float, float]:
        """Give the navigator the SLAM map at global_costmap_rate (whole every
        full_map_check_period); its (wall, CPU) time [s]."""
        p = self.p
        nav_s = cpu_s = 0.0
        if updated and self._map_due(t):
            grid = self.slam.occupancy()
            full = t - self.last_full_t >= p.costmap.full_map_check_period
            c0, u0 = time.perf_counter(), time.thread_time()
            self.nav.update_map(grid.prob, grid.resolution, grid.origin, full)
            nav_s += time.perf_counter() - c0
            cpu_s += time.thread_time() - u0
            self.last_map_t = t
            if full:
                self.last_full_t = t
                # the whole map's temporaries are freed: glibc keeps freed memory in its heap
                # (86 MiB of virginia_cross's run at 1,600 s), so it is given back here
                release_free_heap()
        return nav_s, cpu_s

    def _progress(self, t: float, pose_gt, pose_est, status: str, ranges) -> None:
        """on_progress, with the coverage refreshed every coverage_period."""
        p, nav = self.p, self.nav
        self.next_progress += p.progress_period
        if int(round(t / self.dt)) % max(1, int(round(p.coverage_period / self.dt))) == 0:
            if self.reach_cells is None:
                self.reach_cells = ReachCells(self.reach, self.world.resolution, self.world.origin)
            self.last_cov = _coverage(self.reach_cells, self.slam, self.rec)
        done = sum(g.status in ("reached", "explored") for g in nav.stats.goals)
        goal = None if nav.goal is None else np.asarray(nav.goal.goal_xy, dtype=float)
        live = (goal, nav.path, ranges, self.slam.occupancy)
        self.on_progress(ExploreProgress(t, pose_gt, pose_est, self.last_cov, done, status, *live))

    def _judge(self, stop: StopReason, seen: np.ndarray, cov: float) -> tuple[RunOutcome, str]:
        return judge_outcome(stop, self.passable, seen, self.world, cov, self.p)

    def result(self, stop: StopReason) -> ExplorationResult:
        """The run, ended by `stop`: its recording, final map, coverage and counters."""
        world, sim, rec = self.world, self.sim, self.rec
        nav = self.nav
        goals = tuple(nav.stats.goals)
        safety_triggers, recoveries = nav.safety.n_triggers, nav.stats.recoveries
        # the navigation's map-sized grids (costmap, planner and frontier buffers) and the stop
        # rules' map snapshots are let go before the final map is assembled and judged: the
        # peak of a large plan's run was here, with both alive (virginia_cross: about 100 MiB)
        self.nav = nav = None
        self.rules = ()
        gc.collect()  # the navigator's parts refer to one another
        release_free_heap()
        # with the end-point counts where the SLAM keeps them (the map score's walls)
        grid = getattr(self.slam, "occupancy_with_hits", self.slam.occupancy)()
        pose_gt = rec.buf[: rec.n, 1:4].copy()
        pose_est = rec.buf[: rec.n, 4:7].copy()
        T = align_map_to_world(pose_est, pose_gt)
        seen = seen_free(
            self.reach, world.resolution, world.origin, grid.prob, grid.resolution, grid.origin,
            grid.occ_thresh, T, self.reach_cells,
        )  # fmt: skip
        n_reach = np.count_nonzero(self.reach)
        cov = np.count_nonzero(seen) / n_reach if n_reach else 0.0
        outcome, detail = self._judge(stop, seen, cov)
        if len(pose_gt) and (outcome == RunOutcome.INCOMPLETE or stop.reason == "stuck"):
            detail += "; " + end_pose_error_line(T, pose_est[-1], pose_gt[-1])
        n0 = self.n_collisions0
        col = sim.collisions[n0] if len(sim.collisions) > n0 else None
        final = getattr(self.slam, "final_trajectory", None)
        pose_final = None if final is None else np.asarray(final(), dtype=float)
        if pose_final is not None and pose_final.shape != pose_est.shape:
            pose_final = None  # a step without a scan processed (slam_failed): no 1:1 match
        return ExplorationResult(
            outcome=outcome,
            reason=stop.reason,
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
            safety_triggers=safety_triggers,
            recoveries=recoveries,
            T_world_map=T,
            nav_wall_s=rec.nav[: rec.n].copy(),
            nav_cpu_s=rec.cpu[: rec.n].copy(),
            wall_s=time.perf_counter() - self.wall0,
            pose_final=pose_final,
        )


def end_pose_error_line(T_world_map: np.ndarray, est: np.ndarray, gt: np.ndarray) -> str:
    """Where the SLAM pose was at the end, against the truth, in one clause: a robot stuck or
    giving up with its pose far off drove on a map too wrong to navigate, one with its pose
    right did not (the paths aligned as for the coverage, `align_map_to_world`)."""
    err = se2.relative(gt, se2.compose(T_world_map, est))
    return (
        f"at the end the SLAM pose was {math.hypot(err[0], err[1]):.2f} m and "
        f"{abs(err[2]):.2f} rad from the true one (paths aligned)"
    )


def judge_outcome(
    stop: StopReason, reach: np.ndarray, seen: np.ndarray, world, cov: float, p: ExploreParams
) -> tuple[RunOutcome, str]:
    """The outcome and its line: a run stopped as done (no frontier, map unchanged) that left
    a region of `reach` unseen (`unseen_regions` with incomplete_area, incomplete_width) is
    incomplete: the robot gave up frontiers it could have driven to. The run passes the
    space behind gaps it can drive through (`passable_clearance_m`); `cov` stays the
    coverage of all the reachable space."""
    if stop.outcome != RunOutcome.COMPLETED:
        return stop.outcome, stop.detail
    left = unseen_regions(
        reach, seen, world.resolution, world.origin, p.incomplete_area, p.incomplete_width
    )
    if not left:
        return stop.outcome, stop.detail
    big = left[0]
    area = sum(u.area_m2 for u in left)
    detail = (
        f"{stop.detail}, but {area:.1f} m^2 of reachable space never seen in {len(left)} "
        f"region(s), the largest {big.area_m2:.1f} m^2 at ({big.centre[0]:.1f}, "
        f"{big.centre[1]:.1f})"
    )  # the coverage is the run's own field (the CLI prints it after this line)
    return RunOutcome.INCOMPLETE, detail


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
    The stop rules (stop_rules.default_rules) are asked in order after every control period.
    """
    run = Exploration(world, sim, slam, params or ExploreParams(), oracle, on_progress)
    stop = None
    while stop is None:
        stop = run.step()
    return run.result(stop)


def _coverage(cells: ReachCells, slam, rec: _Recorder) -> float:
    grid = slam.occupancy()
    T = align_map_to_world(rec.buf[: rec.n, 4:7], rec.buf[: rec.n, 1:4])
    return cells.coverage(grid.prob, grid.resolution, grid.origin, grid.occ_thresh, T)
