"""`mapqual batch` and the database: a job per world and condition, a run per seed, found
again by idempotency key on resume; the local pool's runs executed by the run service in its
worker processes (`PoolRun`), and the Celery mode's queue (`DbBatch` is a `RunQueue`)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from backend.core.config import Settings
from backend.db.models import Run
from backend.db.session import session_scope
from backend.services import users
from backend.services.execute import Placement, execute_run
from backend.store import (
    add_job_runs,
    create_job,
    get_runs,
    mark_run_failed,
    requeue_run,
    save_world,
)
from worker.batch.experiment import RunSpec, world_fingerprint
from worker.batch.jobs import plan_cells, source_format
from worker.batch.local import SIM_LOG_GZ, RunOutput, Task, execute, load_cached, throttled
from worker.batch.pool import TaskFailed
from worker.batch.remote import RunState
from worker.status import RunStatus
from worker.world.world import World

if TYPE_CHECKING:
    from worker.pipeline import RunProgress

log = logging.getLogger("mapqual.batch")


class DbBatch:
    """The batch's jobs and runs in the database. The local pool's sink: its worker processes
    claim and store the runs (`PoolRun`); the parent fails the runs whose process died and
    requeues those interrupted. Celery's queue: it reads the runs' state and sends them."""

    def __init__(
        self, settings: Settings, batch_id: str, specs: Sequence[RunSpec], worlds: dict[str, World]
    ):
        self.settings = settings
        self.url = url = settings.database_url
        self.run_ids: dict[str, int] = {}
        self.job_ids: dict[str, int] = {}
        with session_scope(url) as s:
            owner = users.local(s).id
            world_ids: dict[str, int] = {}
            for path, world in worlds.items():
                row = save_world(
                    s, owner_id=owner, world=world, sha256=world_fingerprint(world),
                    source_format=source_format(path),
                )  # fmt: skip
                world_ids[path] = row.id
            for cell in plan_cells(specs):
                job = create_job(
                    s, owner_id=owner, world_id=world_ids[cell.world_path], slam=cell.slam,
                    params=cell.params, seeds=cell.seeds,
                    idempotency_key=cell.idempotency_key(batch_id),
                )  # fmt: skip
                runs = add_job_runs(s, job.id, cell.seeds)
                for spec in cell.specs:
                    self.run_ids[spec.key] = runs[spec.seed].id
                    self.job_ids[spec.key] = job.id

    def run_id(self, spec: RunSpec) -> int:
        """The run's database id."""
        return self.run_ids[spec.key]

    def ids(self, spec: RunSpec) -> dict[str, Any]:
        """The run's and its job's database ids, for its record."""
        return {"run_id": self.run_ids[spec.key], "job_id": self.job_ids[spec.key]}

    def pool_run(self) -> PoolRun:
        """What the local pool's worker processes call for each run."""
        return PoolRun(self.settings, dict(self.run_ids))

    def started(self, spec: RunSpec) -> None:
        """Nothing: the worker process claims the run itself."""

    def finished(self, spec: RunSpec, out: RunOutput) -> dict[str, Any]:
        """Nothing to store: the worker process stored the result with its claim."""
        return self.ids(spec)

    def failed(self, spec: RunSpec, error: str) -> dict[str, Any]:
        """The run's worker process raised or died: a run it had not claimed yet (its world
        did not load) or still held (it died) is failed here; one the run service failed or
        found cancelled is left as it is."""
        run_id = self.run_ids[spec.key]
        with session_scope(self.url) as s:
            run = s.get_one(Run, run_id)
            if run.status == RunStatus.QUEUED:
                mark_run_failed(s, run_id, error, None)
            elif run.status == RunStatus.RUNNING and run.attempt is not None:
                mark_run_failed(s, run_id, error, run.attempt)
        return self.ids(spec)

    def interrupted(self, specs: Sequence[RunSpec]) -> None:
        """Put the runs back to queued, explicitly: runs in flight when this batch stopped,
        or (on resume) runs a killed invocation left running or that failed and are redone."""
        with session_scope(self.url) as s:
            for spec in specs:
                requeue_run(s, self.run_ids[spec.key], "batch resumed or interrupted")

    def states(self, run_ids: Sequence[int]) -> list[RunState]:
        """The runs' state as stored."""
        with session_scope(self.url) as s:
            return [
                RunState(r.id, r.status, r.summary, r.error, r.report_dir, r.progress or {})
                for r in get_runs(s, run_ids)
            ]

    def send(self, run_id: int, requeue: bool) -> None:
        """Queue the run for the Celery workers (`requeue`: a failed run back to queued first:
        the task runs queued runs only)."""
        from backend.core.queue import enqueue_runs

        with session_scope(self.url) as s:
            if requeue:
                requeue_run(s, run_id, "--retry-failed")
            enqueue_runs(s, self.settings.redis_url, [run_id])


@dataclass(frozen=True)
class PoolRun:
    """One run in a local pool's worker process, through the run service: claimed, run into
    its folder in OUT, and stored, all in that process."""

    settings: Settings
    run_ids: dict[str, int]  # run key -> the database's run id

    def __call__(self, task: Task, progress: Callable[[RunProgress], None]) -> RunOutput:
        spec = task.spec
        place = Placement(
            report_dir=Path(task.report_dir), own_folder=True,
            sim_log=SIM_LOG_GZ if task.sim_log else None,
            lease_s=0.0,  # a run still running here is this batch's own: resuming requeued it
        )  # fmt: skip
        world = load_cached(spec.world_path, task.allow_outside)
        outcome = execute_run(
            self.run_ids[spec.key], self.settings, place=place,
            on_progress=throttled(progress), world=world,
        )  # fmt: skip
        if outcome.summary is not None and outcome.report_dir is not None:
            return RunOutput(summary=outcome.summary, report_dir=outcome.report_dir)
        if outcome.found == RunStatus.DONE:
            # stored by a batch killed before it wrote the record: its folder was emptied
            # for this attempt, so write the report again (same seed, same files); the
            # database keeps the result it has
            return execute(task, progress)
        # failed: the record's error is the one stored; cancelled or lost: why not stored
        raise TaskFailed(outcome.error or outcome.message)
