"""One run: world -> simulate -> explore (closed loop with SLAM) -> evaluate; `run_one`."""

from __future__ import annotations

import gzip
import io
import math
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from worker.evaluate.ate import AteResult, absolute_trajectory_error
from worker.evaluate.coverage import reachable_free
from worker.evaluate.map_score import MapScore, MapScoreParams, score_map, start_alignment
from worker.evaluate.metric import RelationErrors, evaluate_relations
from worker.evaluate.relations import (
    Relations,
    RelationsCapWarning,
    relations_A,
    relations_B,
    relations_SM,
)
from worker.evaluate.trajectory import Trajectory
from worker.explore.loop import ExplorationResult, ExploreProgress, explore
from worker.kernel_cache import warm_kernels
from worker.report.summary import RunSummary
from worker.report.timeline import Timeline
from worker.run_params import EvalParams, RunParams
from worker.sim.carmen import CarmenWriter
from worker.sim.simulator import Simulator
from worker.slam import registry
from worker.slam.base import closed_after
from worker.slam.grid import OccupancyGrid
from worker.status import RunOutcome
from worker.world.world import World

__all__ = ["EvalParams", "RunParams", "RunCancelled", "RunSuperseded", "RunResult", "run_one"]


class RunCancelled(Exception):
    """Raised from an `on_progress` callback to stop a run at its next step."""


class RunSuperseded(RunCancelled):
    """Raised from an `on_progress` callback when another attempt now holds the run: this one
    stops and keeps nothing (a run stopped by it is handled as a cancelled one)."""


@dataclass(frozen=True)
class RunProgress:
    """What a running run reports about once per simulated second."""

    t: float  # [s] simulated time
    coverage: float  # [0, 1] latest coverage estimate
    pose_gt: np.ndarray  # (3,) [x, y, theta]
    pose_est: np.ndarray  # (3,) [x, y, theta]
    status: str  # what the navigation stack is doing
    goals_reached: int
    wall_s: float  # [s] since the run started
    rtf: float  # simulated seconds per wall second so far
    # For live viewers (SLAM map frame; None when there is none), as ExploreProgress has them:
    goal_xy: np.ndarray | None = None  # (2,) [m] the current frontier goal
    plan: np.ndarray | None = None  # (K, 2) [m] the global plan
    ranges: np.ndarray | None = None  # (B,) [m] the latest scan
    occupancy: Callable[[], OccupancyGrid] | None = None  # the current map, read on demand
    beam_angles: np.ndarray | None = None  # (B,) [rad] of `ranges`, relative to the heading
    range_max: float = math.inf  # [m] readings at or past this are "no return"
    # under real-time emulation, what the SLAM has kept up with so far (RealtimeSummary's
    # fields: speed, fixed_latency_s, scans, updates, scans_dropped, latency_mean_s / _max_s)
    realtime: dict | None = None


@dataclass(frozen=True, eq=False)
class RunResult:
    """A finished run: its exploration, its relations and errors, and the summary.json."""

    world: World
    seed: int
    params: RunParams
    exploration: ExplorationResult
    gt: Trajectory  # ground truth at 10 Hz
    est: Trajectory  # SLAM estimate at the same timestamps
    relations: dict[str, Relations]  # "B", "A", "SM"
    errors: dict[str, RelationErrors]
    ate: AteResult | None
    summary: RunSummary
    map_score: MapScore | None = None  # the final map against the floorplan
    timeline: Timeline | None = None  # coverage etc. against simulated time (progress reports)


class _TimedSimulator:
    """The simulator as the exploration sees it: times its calls and, given a CARMEN writer,
    logs one tick per scan taken.

    The exploration loop takes exactly one scan per 0.1 s step, at the top of the step, so the
    log holds every scan with the odometry and ground truth of the same instant.
    """

    def __init__(self, sim: Simulator, writer: CarmenWriter | None):
        self._sim = sim
        self._writer = writer
        self.wall_s = 0.0  # [s] spent simulating and logging

    def scan(self) -> np.ndarray:
        t0 = time.perf_counter()
        ranges = self._sim.scan()
        if self._writer is not None:
            v, w = self._sim.velocity
            sim = self._sim
            self._writer.write_tick(sim.t, sim.pose_gt, sim.pose_odom, v, w, ranges)
        self.wall_s += time.perf_counter() - t0
        return ranges

    def step(self, v_cmd: float, w_cmd: float) -> bool:
        t0 = time.perf_counter()
        out = self._sim.step(v_cmd, w_cmd)
        self.wall_s += time.perf_counter() - t0
        return out

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sim, name)


class _TimedSlam:
    """A SLAM algorithm with the wall time of its updates and map reads counted."""

    def __init__(self, slam):
        self._slam = slam
        self.wall_s = 0.0  # [s]

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        t0 = time.perf_counter()
        out = self._slam.process(t, pose_odom, ranges_m)
        self.wall_s += time.perf_counter() - t0
        return out

    def occupancy(self):
        t0 = time.perf_counter()
        out = self._slam.occupancy()
        self.wall_s += time.perf_counter() - t0
        return out

    def __getattr__(self, name: str) -> Any:
        return getattr(self._slam, name)


def run_one(
    world: World,
    params: RunParams,
    seed: int,
    on_progress: Callable[[RunProgress], None] | None = None,
    *,
    sim_log: str | Path | None = None,
) -> RunResult:
    """Simulate, explore with SLAM in closed loop, and evaluate one run of `world`.

    One Generator from `seed` is split into independent streams for the simulator, SLAM and
    the relation sampling, so the same inputs give the same result bit for bit. `sim_log`
    (optional; `.gz` compresses) receives the full CARMEN log with every scan, for replaying
    other SLAM algorithms on the same data. `on_progress` may raise `RunCancelled`.
    The first run of a version compiles the kernels in a child process (worker.kernel_cache).
    """
    warm_kernels(params.algorithm)
    wall0 = time.perf_counter()
    rng_sim, rng_slam, rng_eval = np.random.default_rng(seed).spawn(3)
    entry = registry.get(params.algorithm)
    inner, rt = _make_slam(entry, params, rng_slam)
    slam = _TimedSlam(inner)
    # the progress reports for timeline.csv (without on_progress no coverage is measured)
    timeline = None if on_progress is None else Timeline()
    relay = None if timeline is None else timeline.tap(on_progress)
    callback = None if relay is None else _progress_relay(relay, params, wall0, rt)
    with _open_log(sim_log) as stream, closed_after(slam):
        writer = None
        if stream is not None:
            name = registry.label(params.algorithm, params.slam)
            header = f"mapqual run: world {world.name}, seed {seed}, {name}"
            writer = CarmenWriter(stream, params.sim.laser, comment=header)
        sim = _TimedSimulator(Simulator(world, params.sim, rng_sim), writer)
        exploration = explore(
            world, sim, slam, params.explore, oracle=entry.ground_truth, on_progress=callback
        )
    stage_wall = {"simulation_wall_s": sim.wall_s, "slam_wall_s": slam.wall_s}
    # the SLAM's particle maps and the simulator are done with: their memory is let go before
    # the evaluation's map-sized work (the map score), not after it (issue 21: a run < 1 GB)
    rt_doc = None if rt is None else rt.stats.summary(rt.params.speed, rt.params.fixed_latency_s)
    del sim, slam, inner, rt
    wall_explore = time.perf_counter() - wall0
    gt = Trajectory(exploration.t, exploration.pose_gt)
    est = Trajectory(exploration.t, exploration.pose_est)
    relations, errors = _evaluate(gt, est, params.eval, rng_eval)
    ate = absolute_trajectory_error(gt, est, params.eval.max_gap) if len(gt) > 1 else None
    map_score = _map_score(world, params, exploration)
    wall = time.perf_counter() - wall0
    summary = _summary(
        world, seed, params, exploration, errors, ate, wall_explore, wall, stage_wall
    )
    if map_score is not None:  # an additive section (issue 17), after the rest
        doc = {**summary.to_dict(), "map_score": map_score.summary()}
        summary = RunSummary.model_validate(doc)
    if rt_doc is not None:  # another (issue 51): what the real-time SLAM kept up with
        summary = RunSummary.model_validate({**summary.to_dict(), "realtime": rt_doc})
    return RunResult(
        world, seed, params, exploration, gt, est, relations, errors, ate, summary, map_score,
        timeline,
    )  # fmt: skip


def _make_slam(entry: registry.SlamEntry, params: RunParams, rng: np.random.Generator):
    """(the run's SLAM, its real-time wrapper or None): under `params.realtime` the algorithm
    runs inside a RealtimeSlam (updates take simulated time, scans meanwhile dropped)."""
    inner = entry.factory(params.sim.laser, params.slam, rng)
    if params.realtime is None:
        return inner, None
    from worker.slam.realtime import RealtimeSlam

    rt = RealtimeSlam(inner, params.realtime, params.sim.laser.n_beams)
    return rt, rt


def _map_score(world: World, params: RunParams, ex: ExplorationResult) -> MapScore | None:
    """The final map against the floorplan, registered from the start pose (None: no pose)."""
    if len(ex.pose_gt) == 0:
        return None
    start = ex.pose_gt[0]
    start_cell = (
        int(math.floor((start[0] - world.origin[0]) / world.resolution)),
        int(math.floor((start[1] - world.origin[1]) / world.resolution)),
    )
    reach = reachable_free(
        world.occ, world.resolution, start_cell, params.explore.costmap.footprint_half_m
    )
    T0 = start_alignment(ex.pose_est[0], ex.pose_gt[0])
    p = MapScoreParams().for_laser_noise(params.sim.laser_noise_sigma)
    return score_map(world.occ, world.resolution, world.origin, reach, ex.final_map, T0, p)


def _progress_relay(
    on_progress: Callable[[RunProgress], None], params: RunParams, wall0: float, rt=None
) -> Callable[[ExploreProgress], None]:
    """The exploration's progress callback: each ExploreProgress passed on as a RunProgress
    with the wall time since `wall0`, the laser's geometry and, under real-time emulation (`rt`,
    a RealtimeSlam), its updates, dropped scans and latencies so far."""
    angles = params.sim.laser.angles
    range_max = params.sim.laser.range_max

    def progress(p: ExploreProgress) -> None:
        wall = time.perf_counter() - wall0
        rtf = p.t / wall if wall > 0 else 0.0
        on_progress(
            RunProgress(
                p.t,
                p.coverage,
                p.pose_gt,
                p.pose_est,
                p.status,
                p.goals_reached,
                wall,
                rtf,
                p.goal_xy,
                p.plan,
                p.ranges,
                p.occupancy,
                angles,
                range_max,
                None
                if rt is None
                else rt.stats.summary(rt.params.speed, rt.params.fixed_latency_s),
            )  # fmt: skip
        )

    return progress


@contextmanager
def _open_log(path: str | Path | None) -> Iterator[TextIO | None]:
    if path is None:
        yield None
        return
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".gz":
        # mtime=0: the same run gives the same bytes
        with open(path, "wb") as raw, gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as gz:
            yield io.TextIOWrapper(gz, encoding="utf-8", newline="\n")
    else:
        with open(path, "w", encoding="utf-8", newline="\n") as fh:
            yield fh


def _evaluate(
    gt: Trajectory, est: Trajectory, p: EvalParams, rng: np.random.Generator
) -> tuple[dict[str, Relations], dict[str, RelationErrors]]:
    """B (the score), A and SM relations of the run and the estimate's errors on them."""
    relations: dict[str, Relations] = {}
    if len(gt) >= 2:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RelationsCapWarning)  # the count is in the summary
            relations["B"] = relations_B(gt, est, rng, p.b)
        relations["A"] = relations_A(gt, p.a)
        relations["SM"] = relations_SM(gt, p.sm)
    errors = {k: evaluate_relations(r, est, p.max_gap) for k, r in relations.items()}
    return relations, errors


def _summary(world, seed, params, ex, errors, ate, wall_explore, wall, stage_wall) -> RunSummary:
    """summary.json: outcome and coverage at the top level, each relation kind's figures in
    exactly the shape `mapqual evaluate --json` prints."""
    failed = ex.outcome != RunOutcome.COMPLETED
    sim_time = float(ex.t[-1]) if len(ex.t) else 0.0
    doc = {
        "outcome": ex.outcome,
        "reason": ex.reason if failed else None,
        "stop": ex.reason,
        "stop_detail": ex.stop_detail,
        "coverage": ex.coverage,
        "world": world.name,
        "seed": seed,
        "algorithm": registry.label(params.algorithm, params.slam),
        "relations": {k: e.summary() for k, e in errors.items()},
        "ate": None if ate is None else ate.summary(),
        "path_length_m": ex.path_length_m,
        "collision": None
        if ex.collision is None
        else dict(zip(("t", "x", "y", "theta"), ex.collision, strict=True)),
        "goals": {
            "reached": ex.goals_reached,
            "failed": ex.goals_failed,
            "total": len(ex.goals),
            "look_through": sum(g.detail.startswith("look-through") for g in ex.goals),
            "squeeze": sum(g.detail.startswith("squeeze") for g in ex.goals),
        },
        "safety_triggers": ex.safety_triggers,
        "recoveries": ex.recoveries,
        "timings": {
            "sim_time_s": sim_time,
            "wall_time_s": wall,
            "explore_wall_s": wall_explore,
            "evaluate_wall_s": wall - wall_explore,
            "navigation_wall_s": float(np.sum(ex.nav_wall_s)),
            "real_time_factor": sim_time / wall if wall > 0 else None,
            **stage_wall,
        },
        "params": params.to_json(),
        "versions": _versions(),
    }
    return RunSummary.model_validate(doc)


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    import numba

    try:
        mapqual = version("mapqual")
    except PackageNotFoundError:  # a source tree on sys.path, never installed
        mapqual = "unknown"
    return {"mapqual": mapqual, "numpy": np.__version__, "numba": numba.__version__}
