"""Running a batch's runs in a local process pool: each process executes a run (`execute`, or
the run service that stores it: `backend.services.batch`), and the parent tells a sink (the
database) how each ended and then writes its record (OUT)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from worker.batch.experiment import RunSpec
from worker.batch.pool import PoolMessage, run_pool
from worker.batch.records import BatchRecord
from worker.batch.state import BatchDir, record_of
from worker.report.summary import RunSummary
from worker.status import RecordStatus

if TYPE_CHECKING:
    from worker.pipeline import RunProgress
    from worker.world.world import World

# a run's progress as the batch display takes it: (t [s] simulated, coverage [0, 1])
ProgressFn = Callable[[tuple[float, float]], None]

PROGRESS_EVERY_S = 2.0  # [s] wall time between progress messages from a running run
SIM_LOG_GZ = "sim.log.gz"  # a run's full CARMEN log in its folder, with --sim-log


@dataclass(frozen=True)
class RunOutput:
    """What a finished run sends back to the parent, for its record in OUT (the database, when
    there is one, has the rest: the run service stored it in the worker process)."""

    summary: RunSummary
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
    record: BatchRecord | None = None  # finish
    t: float = 0.0  # [s] simulated time so far (progress)
    coverage: float = 0.0  # progress


class Sink(Protocol):
    """Who hears how runs end besides OUT (the database); called in the parent process only."""

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
def load_cached(path: str, allow_outside: bool = False) -> World:
    """The world of a floorplan file, loaded once per worker process."""
    from worker.world.loader import load_world

    return load_world(Path(path), allow_outside=allow_outside)


def throttled(progress: ProgressFn) -> Callable[[RunProgress], None]:
    """A pipeline progress callback that passes (t [s], coverage) to `progress` at most once
    every PROGRESS_EVERY_S of wall time."""
    last = [0.0]

    def on_progress(p: RunProgress) -> None:
        now = time.monotonic()
        if now - last[0] >= PROGRESS_EVERY_S:
            last[0] = now
            progress((float(p.t), float(p.coverage)))

    return on_progress


def execute(task: Task, progress: ProgressFn) -> RunOutput:
    """One run in a worker process with no database: `run_one`, then its report folder."""
    from worker.pipeline import run_one
    from worker.report.folder import write_report
    from worker.run_params import RunParams

    spec = task.spec
    out = Path(task.report_dir)
    log = out / SIM_LOG_GZ if task.sim_log else None
    params = RunParams.from_json(spec.params)
    world = load_cached(spec.world_path, task.allow_outside)
    result = run_one(world, params, spec.seed, throttled(progress), sim_log=log)
    write_report(result, out)
    return RunOutput(summary=result.summary, report_dir=str(out.resolve()))


def run_local(
    specs: Sequence[RunSpec],
    bdir: BatchDir,
    workers: int,
    sink: Sink,
    on_event: Callable[[Event], None],
    *,
    sim_log: bool = False,
    allow_outside: bool = False,
    fn: Callable[[Task, ProgressFn], RunOutput] = execute,
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


def _finish(bdir: BatchDir, spec: RunSpec, record: BatchRecord, on_event) -> None:
    bdir.write_record(record)
    bdir.journal(RecordStatus(record["status"]), spec.key)
    on_event(Event("finish", spec, record=record))
