"""Running a batch's runs in a local process pool: each process calls `run_one`, and the
parent persists each result (through a sink: the database) and then its record (OUT)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from worker.batch.experiment import RunSpec
from worker.batch.pool import PoolMessage, run_pool
from worker.batch.state import BatchDir, record_of
from worker.report.summary import RunSummary

PROGRESS_EVERY_S = 2.0  # [s] wall time between progress messages from a running run


@dataclass(frozen=True)
class RunOutput:
    """What a finished run sends back to the parent: the summary and what the database keeps."""

    summary: RunSummary
    t: np.ndarray  # (N,) [s]
    pose_gt: np.ndarray  # (N, 3) [x, y, theta]
    pose_est: np.ndarray  # (N, 3) [x, y, theta]
    map_ros: np.ndarray  # (H, W) int8, -1 unknown, 0..100
    map_resolution: float  # [m/cell]
    map_origin: tuple[float, float]  # [m]
    report_dir: str


@dataclass(frozen=True)
class Task:
    """A run as handed to a worker process."""

    spec: RunSpec
    report_dir: str
    sim_log: bool  # also write the full CARMEN log (sim.log.gz, every scan: large)
    allow_outside: bool = False  # the world's files may lie outside its folder (--allow-outside)


@dataclass(frozen=True)
class Event:
    """What the batch tells its display: a run `start`ed, its `progress`, or it `finish`ed."""

    kind: str  # start | progress | finish
    spec: RunSpec
    record: dict[str, Any] | None = None  # finish
    t: float = 0.0  # [s] simulated time so far (progress)
    coverage: float = 0.0  # progress


class Sink(Protocol):
    """Where results go besides OUT (the database); called in the parent process only."""

    def started(self, spec: RunSpec) -> None: ...
    def finished(self, spec: RunSpec, out: RunOutput) -> dict[str, Any]: ...
    def failed(self, spec: RunSpec, error: str) -> dict[str, Any]: ...
    def interrupted(self, specs: Sequence[RunSpec]) -> None: ...


class NullSink:
    """Results in OUT only."""

    def started(self, spec: RunSpec) -> None:
        pass

    def finished(self, spec: RunSpec, out: RunOutput) -> dict[str, Any]:
        return {}

    def failed(self, spec: RunSpec, error: str) -> dict[str, Any]:
        return {}

    def interrupted(self, specs: Sequence[RunSpec]) -> None:
        pass


@lru_cache(maxsize=8)
def _world(path: str, allow_outside: bool = False):
    from worker.world.loader import load_world

    return load_world(Path(path), allow_outside=allow_outside)


def execute(task: Task, progress: Callable[[Any], None]) -> RunOutput:
    """One run in a worker process: `run_one`, then its report folder."""
    from worker.pipeline import RunParams, run_one
    from worker.report.folder import write_report

    spec = task.spec
    last = [0.0]

    def on_progress(p) -> None:
        now = time.monotonic()
        if now - last[0] >= PROGRESS_EVERY_S:
            last[0] = now
            progress((float(p.t), float(p.coverage)))

    out = Path(task.report_dir)
    log = out / "sim.log.gz" if task.sim_log else None
    params = RunParams.from_json(spec.params)
    result = run_one(
        _world(spec.world_path, task.allow_outside), params, spec.seed, on_progress, sim_log=log
    )
    write_report(result, out)
    ex = result.exploration
    return RunOutput(
        summary=result.summary,
        t=ex.t,
        pose_gt=ex.pose_gt,
        pose_est=ex.pose_est,
        map_ros=ex.final_map.to_ros(),
        map_resolution=float(ex.final_map.resolution),
        map_origin=(float(ex.final_map.origin[0]), float(ex.final_map.origin[1])),
        report_dir=str(out.resolve()),
    )


def run_local(
    specs: Sequence[RunSpec],
    bdir: BatchDir,
    workers: int,
    sink: Sink,
    on_event: Callable[[Event], None],
    *,
    sim_log: bool = False,
    allow_outside: bool = False,
    fn: Callable[[Task, Callable[[Any], None]], RunOutput] = execute,
) -> None:
    """Run `specs` (the unfinished runs) in `workers` processes. Each run is persisted to the
    sink, then recorded in OUT; an error fails that run only. Interrupted, the runs in flight
    are handed back to the sink (requeued) and the KeyboardInterrupt propagates."""
    tasks = [Task(s, str(bdir.run_dir(s.key)), sim_log, allow_outside) for s in specs]
    in_flight: dict[int, RunSpec] = {}

    def handle(msg: PoolMessage) -> None:
        spec = specs[msg.index]
        if msg.kind == "started":
            # in flight before the sink hears of it: an interrupt landing inside
            # sink.started (after its commit) must still requeue the run
            in_flight[msg.index] = spec
            bdir.fresh_run_dir(spec.key)
            sink.started(spec)
            bdir.journal("start", spec.key)
            on_event(Event("start", spec))
        elif msg.kind == "progress":
            t, cov = msg.payload
            on_event(Event("progress", spec, t=t, coverage=cov))
        elif msg.kind == "result":
            ids = sink.finished(spec, msg.payload)
            out = msg.payload
            record = record_of(spec, summary=out.summary, report_dir=out.report_dir, **ids)
            _finish(bdir, in_flight.pop(msg.index), record, on_event)
        else:
            ids = sink.failed(spec, msg.payload)
            report_dir = str(bdir.run_dir(spec.key).resolve())
            record = record_of(spec, summary=None, error=msg.payload, report_dir=report_dir, **ids)
            _finish(bdir, in_flight.pop(msg.index), record, on_event)

    try:
        run_pool(fn, tasks, workers, handle)
    except BaseException:
        if in_flight:
            sink.interrupted(list(in_flight.values()))
            for spec in in_flight.values():
                bdir.journal("interrupted", spec.key)
        raise


def _finish(bdir: BatchDir, spec: RunSpec, record: dict[str, Any], on_event) -> None:
    bdir.write_record(record)
    bdir.journal("done" if record["status"] == "done" else "error", spec.key)
    on_event(Event("finish", spec, record=record))
