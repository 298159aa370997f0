"""A batch on Celery workers: send the unfinished runs, then poll their state and record each
as it finishes. The database is reached through a `RunQueue` (`backend.services.batch` is the
one)."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from worker.batch.experiment import RunSpec
from worker.batch.local import Event
from worker.batch.records import BatchRecord
from worker.batch.state import BatchDir, record_of
from worker.report.summary import RunSummary
from worker.status import ACTIVE_RUN, RecordStatus, RunStatus

POLL_S = 1.0  # [s] between polls of the runs' state while Celery workers run the batch


@dataclass(frozen=True)
class RunState:
    """What the batch reads back of one stored run."""

    id: int
    status: str  # queued | running | done | failed | cancelled
    summary: dict[str, Any] | None = None  # as stored (RunSummary.load reads it)
    error: str | None = None
    report_dir: str | None = None
    progress: dict[str, Any] = field(default_factory=dict)


class RunQueue(Protocol):
    """The batch's runs as the database holds them, and the queue they are sent to."""

    def run_id(self, spec: RunSpec) -> int: ...
    def ids(self, spec: RunSpec) -> dict[str, Any]: ...
    def states(self, run_ids: Sequence[int]) -> list[RunState]: ...
    def send(self, run_id: int, requeue: bool) -> None: ...


def record_from_run(spec: RunSpec, run: RunState, ids: dict[str, Any]) -> BatchRecord | None:
    """The OUT record of a run the database holds as finished, or None while it is not."""
    if run.status == RunStatus.DONE:
        return record_of(
            spec, summary=RunSummary.load(run.summary), report_dir=run.report_dir, **ids
        )
    if run.status in (RunStatus.FAILED, RunStatus.CANCELLED):
        error = run.error or RunStatus.CANCELLED.value
        return record_of(spec, summary=None, error=error, report_dir=run.report_dir, **ids)
    return None


def run_celery(
    specs: Sequence[RunSpec],
    bdir: BatchDir,
    queue: RunQueue,
    on_event: Callable[[Event], None],
    *,
    retry_failed: bool = False,
) -> None:
    """Send the unfinished runs to the workers, wait, and record each as it finishes.

    A run sent by an earlier invocation of this batch (the journal says so) is not sent
    again while the database shows it queued or running: killing this command loses nothing,
    the workers carry on and a re-run collects their results.
    """
    by_id = {queue.run_id(s): s for s in specs}
    _send(by_id, bdir, queue, retry_failed)
    waiting = dict(by_id)
    started: set[int] = set()
    while waiting:
        for run in queue.states(list(waiting)):
            spec = waiting[run.id]
            record = record_from_run(spec, run, queue.ids(spec))
            if record is not None:
                bdir.write_record(record)
                bdir.journal(RecordStatus(record["status"]), spec.key)
                on_event(Event("finish", spec, record=record))
                del waiting[run.id]
            elif run.status == RunStatus.RUNNING:
                if run.id not in started:
                    started.add(run.id)
                    on_event(Event("start", spec))
                p = run.progress
                on_event(
                    Event("progress", spec, t=p.get("t", 0.0), coverage=p.get("coverage", 0.0))
                )
        if waiting:
            time.sleep(POLL_S)


def _send(by_id: dict[int, RunSpec], bdir: BatchDir, queue: RunQueue, retry_failed: bool) -> None:
    """Send the runs not sent yet (and, with `retry_failed`, the failed ones, requeued)."""
    sent = {e["run_id"] for e in bdir.read_journal() if e["event"] == "enqueued"}
    status = {r.id: r.status for r in queue.states(list(by_id))}
    for run_id, spec in by_id.items():
        fresh = status.get(run_id) in ACTIVE_RUN and run_id not in sent
        retry = retry_failed and status.get(run_id) == RunStatus.FAILED
        if fresh or retry:
            queue.send(run_id, requeue=retry)
            bdir.journal("enqueued", spec.key, run_id=run_id)
