"""`mapqual batch` and the database: a job per world and condition, a run per seed; and the
Celery mode, which enqueues those runs with the API's task and collects their results."""

from __future__ import annotations

import hashlib
import json
import logging
import time
from collections.abc import Callable, Sequence
from typing import Any

from worker.batch.experiment import RunSpec
from worker.batch.local import Event, RunOutput
from worker.batch.state import BatchDir, record_of
from worker.report.summary import RunSummary
from worker.world.world import World

log = logging.getLogger("mapqual.batch")
POLL_S = 1.0  # [s] between database polls while Celery workers run the batch


def _cell(spec: RunSpec) -> str:
    """A job's identity inside a batch: the world and every parameter, all but the seed."""
    doc = json.dumps([spec.world_path, spec.world, spec.params], sort_keys=True)
    return hashlib.sha256(doc.encode()).hexdigest()[:16]


class DbBatch:
    """The batch's jobs and runs in the database (found again by idempotency key on resume);
    also the local pool's sink: it marks runs started, stores results, records failures."""

    def __init__(self, url: str, batch_id: str, specs: Sequence[RunSpec], worlds: dict[str, World]):
        from backend.db.session import session_scope
        from backend.store import add_job_runs, create_job, local_user, save_world
        from worker.batch.experiment import world_fingerprint

        self.url = url
        self.attempts: dict[str, str | None] = {}  # the local pool's attempt of each run
        self.run_ids: dict[str, int] = {}
        self.job_ids: dict[str, int] = {}
        cells: dict[str, list[RunSpec]] = {}
        for spec in specs:
            cells.setdefault(_cell(spec), []).append(spec)
        with session_scope(url) as s:
            owner = local_user(s).id
            world_ids: dict[str, int] = {}
            for path, world in worlds.items():
                fmt = "stage" if path.endswith(".world") else "yaml"
                row = save_world(
                    s, owner_id=owner, world=world, sha256=world_fingerprint(world),
                    source_format=fmt,
                )  # fmt: skip
                world_ids[path] = row.id
            for cell, group in cells.items():
                first = group[0]
                seeds = [g.seed for g in group]
                job = create_job(
                    s, owner_id=owner, world_id=world_ids[first.world_path], slam=first.slam,
                    params=first.params, seeds=seeds, idempotency_key=f"batch:{batch_id}:{cell}",
                )  # fmt: skip
                runs = add_job_runs(s, job.id, seeds)
                for g in group:
                    self.run_ids[g.key] = runs[g.seed].id
                    self.job_ids[g.key] = job.id

    def ids(self, spec: RunSpec) -> dict[str, Any]:
        """The run's and its job's database ids, for its record."""
        return {"run_id": self.run_ids[spec.key], "job_id": self.job_ids[spec.key]}

    def started(self, spec: RunSpec) -> None:
        """Claim the run under a new attempt of this process (a run the database holds as done
        already, the batch killed before its record was written, is kept as it is)."""
        from backend.db.session import session_scope
        from backend.lifecycle import claim_run, new_attempt

        attempt = new_attempt()
        with session_scope(self.url) as s:
            # no lease: the local pool writes no heartbeat, and a run still running here is
            # this batch's own (resuming requeued those a killed invocation left)
            _, run = claim_run(s, self.run_ids[spec.key], attempt, lease_s=0.0)
        self.attempts[spec.key] = attempt if run is not None else None

    def finished(self, spec: RunSpec, out: RunOutput) -> dict[str, Any]:
        from backend.db.session import session_scope
        from backend.lifecycle import TransitionRefused
        from backend.store import store_run_result

        attempt = self.attempts.pop(spec.key, None)
        if attempt is None:
            return self.ids(spec)
        try:
            with session_scope(self.url) as s:
                store_run_result(
                    s, self.run_ids[spec.key], summary=out.summary, t=out.t,
                    pose_gt=out.pose_gt, pose_est=out.pose_est, map_ros=out.map_ros,
                    map_resolution=out.map_resolution, map_origin=out.map_origin,
                    report_dir=out.report_dir, attempt=attempt,
                )  # fmt: skip
        except TransitionRefused as exc:  # cancelled or requeued meanwhile: not this result
            log.warning("%s", exc)
        return self.ids(spec)

    def failed(self, spec: RunSpec, error: str) -> dict[str, Any]:
        from backend.db.session import session_scope
        from backend.store import mark_run_failed

        attempt = self.attempts.pop(spec.key, None)
        if attempt is not None:
            with session_scope(self.url) as s:
                mark_run_failed(s, self.run_ids[spec.key], error, attempt)
        return self.ids(spec)

    def interrupted(self, specs: Sequence[RunSpec]) -> None:
        """Put the runs back to queued, explicitly: runs in flight when this batch stopped,
        or (on resume) runs a killed invocation left running or that failed and are redone."""
        from backend.db.session import session_scope
        from backend.store import requeue_run

        with session_scope(self.url) as s:
            for spec in specs:
                requeue_run(s, self.run_ids[spec.key], "batch resumed or interrupted")
                self.attempts.pop(spec.key, None)


def _record_from_run(spec: RunSpec, run: Any, ids: dict[str, Any]) -> dict[str, Any] | None:
    """The OUT record of a run the database holds as finished, or None while it is not."""
    if run.status == "done":
        summary = RunSummary.load(run.summary)
        return record_of(spec, summary=summary, report_dir=run.report_dir, **ids)
    if run.status in ("failed", "cancelled"):
        error = run.error or "cancelled"
        return record_of(spec, summary=None, error=error, report_dir=run.report_dir, **ids)
    return None


def run_celery(
    specs: Sequence[RunSpec],
    bdir: BatchDir,
    db: DbBatch,
    broker_url: str,
    on_event: Callable[[Event], None],
    *,
    retry_failed: bool = False,
) -> None:
    """Enqueue the unfinished runs with the API's task, wait, and record each as it finishes.

    A run enqueued by an earlier invocation of this batch (the journal says so) is not sent
    again while the database shows it queued or running: killing this command loses nothing,
    the workers carry on and a re-run collects their results.
    """
    from backend.db.session import session_scope
    from backend.queue import enqueue_runs
    from backend.store import get_runs, requeue_run

    sent = {e["run_id"] for e in bdir.read_journal() if e["event"] == "enqueued"}
    by_id = {db.run_ids[s.key]: s for s in specs}
    with session_scope(db.url) as s:
        status = {r.id: r.status for r in get_runs(s, list(by_id))}
    for run_id, spec in by_id.items():
        fresh = status.get(run_id) in ("queued", "running") and run_id not in sent
        retry = retry_failed and status.get(run_id) == "failed"
        if fresh or retry:
            with session_scope(db.url) as s:
                if retry:  # failed -> queued, explicitly: the task runs queued runs only
                    requeue_run(s, run_id, "--retry-failed")
                enqueue_runs(s, broker_url, [run_id])
            bdir.journal("enqueued", spec.key, run_id=run_id)
    waiting = dict(by_id)
    started: set[int] = set()
    while waiting:
        with session_scope(db.url) as s:
            runs = get_runs(s, list(waiting))
        for run in runs:
            spec = waiting[run.id]
            record = _record_from_run(spec, run, db.ids(spec))
            if record is not None:
                bdir.write_record(record)
                bdir.journal("done" if record["status"] == "done" else "error", spec.key)
                on_event(Event("finish", spec, record=record))
                del waiting[run.id]
            elif run.status == "running":
                if run.id not in started:
                    started.add(run.id)
                    on_event(Event("start", spec))
                p = run.progress or {}
                on_event(
                    Event("progress", spec, t=p.get("t", 0.0), coverage=p.get("coverage", 0.0))
                )
        if waiting:
            time.sleep(POLL_S)
