"""Run status changes as compare-and-set updates, each with its line in the run's history.

A run moves only along `LEGAL`; every change is one `UPDATE runs ... WHERE id = :id AND
status = :seen AND attempt = :seen_attempt` whose row count is checked, and the `RunEvent`
recording it is written in the same transaction. Every change first locks the run's job row
(PostgreSQL; SQLite has one writer at a time anyway): changes to the runs of one job are
serialised, so a job's status is computed from its runs' committed states, and two changes
never take the job and run locks in opposite orders.

An attempt (one execution of a run, by a worker or the CLI) holds the run from its claim
until it stores the result or a failure; only the holder may, and a holder that gave no sign
of life for the lease is taken over by the next delivery.
"""

from __future__ import annotations

import functools
import secrets
import shutil
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any, Literal, ParamSpec, TypeVar

from sqlalchemy import ColumnElement, or_, select, update
from sqlalchemy.orm import Session

from backend.db.models import Job, Run, RunEvent, utcnow
from worker.status import ACTIVE_RUN, JobStatus, RunStatus

# (from, to): claim, take over a silent attempt, finish, fail, cancel, and the explicit
# requeue of a failed or interrupted run (batch resume, --retry-failed). queued -> failed is a
# run the API could not send to the queue at all. done and cancelled are final.
LEGAL: frozenset[tuple[RunStatus, RunStatus]] = frozenset(
    {
        (RunStatus.QUEUED, RunStatus.RUNNING),
        (RunStatus.RUNNING, RunStatus.RUNNING),
        (RunStatus.RUNNING, RunStatus.DONE),
        (RunStatus.RUNNING, RunStatus.FAILED),
        (RunStatus.QUEUED, RunStatus.CANCELLED),
        (RunStatus.RUNNING, RunStatus.CANCELLED),
        (RunStatus.FAILED, RunStatus.QUEUED),
        (RunStatus.RUNNING, RunStatus.QUEUED),
        (RunStatus.QUEUED, RunStatus.FAILED),
    }
)
FINAL = frozenset({RunStatus.DONE, RunStatus.CANCELLED})
RETRIES = 5  # compare-and-sets lost to a race before giving up (SQLite only; see _Stale)
P = ParamSpec("P")
T = TypeVar("T")
# besides the run's own status when it is final or failed (done | cancelled | failed)
ClaimAnswer = Literal["claimed", "busy", "missing"] | RunStatus


class TransitionRefused(RuntimeError):
    """A status change whose compare-and-set found the run in another state (or attempt)."""

    def __init__(self, run_id: int, to: RunStatus, found: str | None):
        super().__init__(f"run {run_id}: cannot go to {to} from {found or 'nowhere'}")
        self.run_id, self.to, self.found = run_id, to, found


class _Stale(TransitionRefused):
    """The run changed between the read and the compare-and-set (SQLite, whose reads take no
    lock): read it again and decide again."""


def _retried(fn: Callable[P, T]) -> Callable[P, T]:
    """`fn` again, from a fresh read, when its compare-and-set lost a race (a few times)."""

    @functools.wraps(fn)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> T:
        for _ in range(RETRIES - 1):
            try:
                return fn(*args, **kwargs)
            except _Stale:
                continue
        return fn(*args, **kwargs)

    return wrapper


@dataclass(frozen=True)
class RunState:
    """What a compare-and-set compares against: the run's status and holder, as read."""

    run_id: int
    job_id: int
    status: RunStatus
    attempt: str | None
    heartbeat_at: datetime | None


def new_attempt() -> str:
    """A random attempt id (32 hex characters, as `Run.attempt` holds)."""
    return secrets.token_hex(16)


def _begin(session: Session, run_id: int) -> RunState | None:
    """Lock the run's job, then read the run's state (None for a run that does not exist)."""
    job_id = session.scalar(select(Run.job_id).where(Run.id == run_id))
    if job_id is None:
        return None
    session.flush()  # the caller's pending ORM changes go first, under the same lock
    session.execute(select(Job.id).where(Job.id == job_id).with_for_update())
    row = session.execute(
        select(Run.status, Run.attempt, Run.heartbeat_at).where(Run.id == run_id)
    ).one()
    return RunState(run_id, job_id, row.status, row.attempt, row.heartbeat_at)


def _apply(
    session: Session,
    cur: RunState,
    to: RunStatus,
    *,
    values: dict[str, Any],
    detail: str | None,
    attempt: str | None,
    where: Sequence[ColumnElement[bool]] = (),
) -> Run:
    """The compare-and-set itself, its history line and the job's status; the fresh Run."""
    if (cur.status, to) not in LEGAL:
        raise TransitionRefused(cur.run_id, to, cur.status)
    held = Run.attempt.is_(None) if cur.attempt is None else Run.attempt == cur.attempt
    stmt = (
        update(Run)
        .where(Run.id == cur.run_id, Run.status == cur.status, held, *where)
        .values(status=to, **values)
        .execution_options(synchronize_session=False)
    )
    if session.execute(stmt).rowcount != 1:
        raise _Stale(cur.run_id, to, cur.status)
    session.add(
        RunEvent(
            run_id=cur.run_id, attempt=attempt, from_status=cur.status, to_status=to,
            detail=detail, at=utcnow(),
        )
    )  # fmt: skip
    refresh_job_status(session, session.get_one(Job, cur.job_id, populate_existing=True))
    # the ORM copy (e.g. in job.runs) would otherwise still show the state before the update
    return session.get_one(Run, cur.run_id, populate_existing=True)


@_retried
def claim_run(
    session: Session, run_id: int, attempt: str, lease_s: float
) -> tuple[ClaimAnswer, Run | None]:
    """Make `attempt` the run's holder: a queued run, or a running one whose holder gave no
    sign of life for `lease_s`. Otherwise why not: busy (a live attempt holds it), or the
    run's final or failed status, or missing."""
    cur = _begin(session, run_id)
    if cur is None:
        return "missing", None
    now = utcnow()
    cutoff = now - timedelta(seconds=lease_s)
    where: list[ColumnElement[bool]] = []
    if cur.status == RunStatus.RUNNING:
        if cur.heartbeat_at is not None and cur.heartbeat_at > cutoff:
            return "busy", None
        where.append(or_(Run.heartbeat_at.is_(None), Run.heartbeat_at <= cutoff))
        detail = f"took over from attempt {cur.attempt}: no sign of life for {lease_s:g} s"
    elif cur.status == RunStatus.QUEUED:
        detail = "claimed"
    else:
        return cur.status, None  # done | cancelled | failed
    values = {
        "attempt": attempt, "attempts": Run.attempts + 1, "heartbeat_at": now, "started_at": now,
        "finished_at": None, "error": None, "progress": {},
    }  # fmt: skip
    return "claimed", _apply(
        session, cur, RunStatus.RUNNING, values=values, detail=detail, attempt=attempt, where=where
    )


def _holder_check(
    cur: RunState | None, run_id: int, to: RunStatus, attempt: str | None
) -> RunState:
    """The state, if `attempt` (None: whichever attempt) holds the running run."""
    if cur is None or cur.status != RunStatus.RUNNING:
        raise TransitionRefused(run_id, to, None if cur is None else cur.status)
    if attempt is not None and cur.attempt != attempt:
        raise TransitionRefused(run_id, to, f"running under another attempt ({cur.attempt})")
    return cur


@_retried
def finish_run(session: Session, run_id: int, attempt: str | None, values: dict[str, Any]) -> Run:
    """running -> done by its holder (None: by whichever attempt holds it), with `values`."""
    cur = _holder_check(_begin(session, run_id), run_id, RunStatus.DONE, attempt)
    values = {**values, "finished_at": utcnow(), "error": None}
    return _apply(session, cur, RunStatus.DONE, values=values, detail=None, attempt=cur.attempt)


@_retried
def fail_run(session: Session, run_id: int, error: str, attempt: str | None) -> bool:
    """running -> failed by its holder `attempt`, or (None) queued -> failed for a run that
    could not be sent to the queue; False when the run is not the caller's to fail (a
    cancelled run stays cancelled, a run another attempt holds is left to it)."""
    cur = _begin(session, run_id)
    expected = RunStatus.QUEUED if attempt is None else RunStatus.RUNNING
    if cur is None or cur.status != expected or (attempt is not None and cur.attempt != attempt):
        return False
    values = {"error": error, "finished_at": utcnow()}
    _apply(session, cur, RunStatus.FAILED, values=values, detail=error[:500], attempt=cur.attempt)
    return True


@_retried
def cancel_run(session: Session, run_id: int, detail: str = RunStatus.CANCELLED.value) -> bool:
    """queued | running -> cancelled (a running attempt notices at its next progress write);
    False for a run already finished."""
    cur = _begin(session, run_id)
    if cur is None or cur.status not in ACTIVE_RUN:
        return False
    values = {"finished_at": utcnow()}
    _apply(session, cur, RunStatus.CANCELLED, values=values, detail=detail, attempt=cur.attempt)
    return True


@_retried
def requeue(session: Session, run_id: int, detail: str) -> bool:
    """failed | running -> queued, explicitly (a batch resumes or retries it): the attempt
    that held it, if alive, is superseded at its next progress write. False otherwise."""
    cur = _begin(session, run_id)
    if cur is None or cur.status not in (RunStatus.FAILED, RunStatus.RUNNING):
        return False
    values = {
        "attempt": None, "heartbeat_at": None, "started_at": None, "finished_at": None,
        "error": None, "progress": {},
    }  # fmt: skip
    _apply(session, cur, RunStatus.QUEUED, values=values, detail=detail, attempt=cur.attempt)
    return True


def refresh_job_status(session: Session, job: Job) -> None:
    """A job's status follows its runs: cancelled, running, queued, failed, or done."""
    session.flush()
    if job.status == JobStatus.CANCELLED:
        return
    # from the database, not job.runs: a compare-and-set updates rows the ORM has not seen
    states = set(session.scalars(select(Run.status).where(Run.job_id == job.id).distinct()))
    if RunStatus.RUNNING in states or (RunStatus.QUEUED in states and len(states) > 1):
        job.status = JobStatus.RUNNING
    elif states == {RunStatus.QUEUED}:
        job.status = JobStatus.QUEUED
    elif RunStatus.FAILED in states:
        job.status = JobStatus.FAILED
    else:
        job.status = JobStatus.DONE
    job.updated_at = utcnow()


def history(session: Session, run_id: int) -> list[RunEvent]:
    """The run's status changes, oldest first."""
    stmt = select(RunEvent).where(RunEvent.run_id == run_id).order_by(RunEvent.id)
    return list(session.scalars(stmt))


def history_faults(events: Iterable[RunEvent]) -> list[str]:
    """What is wrong with a run's history (nothing, for a legal one): each change legal and
    starting where the previous one ended, nothing after a final status, and a result or
    failure stored only by the attempt that held the run."""
    faults: list[str] = []
    status, holder = RunStatus.QUEUED, None
    for i, e in enumerate(events):
        if e.from_status != status:
            faults.append(f"event {i}: from {e.from_status}, but the run was {status}")
        if (e.from_status, e.to_status) not in LEGAL:
            faults.append(f"event {i}: {e.from_status} -> {e.to_status} is not legal")
        if (
            e.to_status in (RunStatus.DONE, RunStatus.FAILED)
            and e.from_status == RunStatus.RUNNING
            and e.attempt != holder
        ):
            faults.append(f"event {i}: {e.to_status} by {e.attempt}, not the holder {holder}")
        if e.to_status == RunStatus.RUNNING:
            holder = e.attempt
        status = e.to_status
    return faults


# --- attempt folders -------------------------------------------------------------------------


def attempt_dir(final_dir: Path, attempt: str) -> Path:
    """Where an attempt writes its report: beside the run's folder, named after the attempt."""
    return final_dir.with_name(f"{final_dir.name}.attempt-{attempt}")


def move_into_place(src: Path, final_dir: Path) -> None:
    """Rename the holder's attempt folder to the run's folder (inside the transaction that
    stores its result). A run folder already there is the leftover of an attempt that crashed
    between its rename and its commit (the run is not done, or this attempt could not be
    storing it): it goes first."""
    if final_dir.exists():
        shutil.rmtree(final_dir)
    if src.exists():
        src.rename(final_dir)


def remove_attempt_dirs(final_dir: Path) -> None:
    """Delete what attempts that lost (killed, superseded) left beside the run's folder."""
    for path in final_dir.parent.glob(f"{final_dir.name}.attempt-*"):
        shutil.rmtree(path, ignore_errors=True)
