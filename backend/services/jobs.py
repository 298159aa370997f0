"""Jobs: submit runs of a world (quotas, idempotency, the queue), list and read jobs, cancel
one. What POST/GET /jobs, the dashboard's jobs pages and its form call."""

from __future__ import annotations

import json
from functools import lru_cache

from sqlalchemy import bindparam, func, select
from sqlalchemy.orm import Session

from backend.core.config import Settings
from backend.core.queue import EPOCH_MAX_AGE_S, broker_epoch, send_runs
from backend.core.schemas import JobIn, JobOut, JobPage
from backend.db.models import Job, Run, User, World
from backend.services import quotas
from backend.services.access import Principal, owned
from backend.services.errors import Conflict, Unavailable
from backend.services.external_slam import resolve_external
from backend.store import create_job, mark_run_failed
from backend.store.lifecycle import cancel_run
from worker.run_params import RunParams  # light: no numba in the API process
from worker.slam import registry
from worker.status import JobStatus, WorldStatus

QUEUE_DOWN = "the job queue is unreachable; try again later"


@lru_cache(maxsize=256)
def _run_params(overrides_json: str) -> tuple[str, RunParams, str]:
    """(algorithm's label, RunParams, their JSON text) for the overrides: validated by the
    pipeline's own rules (InputError -> 400), once per distinct set of overrides; the label of
    an external program is external:NAME."""
    params = RunParams.from_json(json.loads(overrides_json))
    return registry.label(params.algorithm, params.slam), params, json.dumps(params.to_json())


_WORLD_OWNER = select(World.owner_id, World.status).where(World.id == bindparam("world_id"))
# The same, taking the submitting user's row as the quota check needs (PostgreSQL: FOR NO KEY
# UPDATE OF users, see `quotas.lock_owner`): one statement where the check would add another.
_WORLD_OWNER_LOCKING_USER = (
    select(World.owner_id, World.status)
    .join(User, User.id == bindparam("user_id"))
    .where(World.id == bindparam("world_id"))
    .with_for_update(of=User, key_share=True)
)


def submit(
    session: Session,
    user: Principal,
    settings: Settings,
    body: JobIn,
    idempotency_key: str | None,
) -> JobOut:
    """Store a job of one queued run per seed and algorithm and queue its runs; the same
    idempotency key again returns the same job."""
    # on PostgreSQL the user's row is locked with the first read (held to the commit), so the
    # quota check below counts with no other submit of this user in between; SQLite has no row
    # locks, and the check takes the database's write lock itself
    locked = session.get_bind().dialect.name == "postgresql"
    stmt = _WORLD_OWNER_LOCKING_USER if locked else _WORLD_OWNER
    world = (
        session.connection().execute(stmt, {"world_id": body.world_id, "user_id": user.id}).first()
    )
    owned(user, world, "world", body.world_id)
    if world.status != WorldStatus.READY:  # pending (being analysed) or invalid: nothing to run on
        raise Conflict(
            f"world {body.world_id} is {world.status}, not ready: runs need an analysed world"
        )
    algorithm, variants = _variants(body, settings)
    if idempotency_key is not None:
        found = session.scalars(
            select(Job).where(Job.owner_id == user.id, Job.idempotency_key == idempotency_key)
        ).first()
        if found is not None:
            return JobOut.of(found)
    try:
        # asked before anything is stored: a broker that cannot be reached leaves no job behind
        epoch = broker_epoch(settings.redis_url, max_age_s=EPOCH_MAX_AGE_S)
    except Exception:
        raise Unavailable(QUEUE_DOWN) from None
    seeds, first = body.seed_list(), variants[0][1]
    quotas.check_runs(session, user.id, settings, len(seeds) * len(variants), first, locked=locked)
    job = create_job(
        session, owner_id=user.id, world_id=body.world_id, slam=algorithm, seeds=seeds,
        # the stored JSON parsed afresh for each job (the cached text is shared)
        variants=[(label, json.loads(text)) for label, _, text in variants],
        idempotency_key=idempotency_key, broker_epoch=epoch, checked=True,
    )  # fmt: skip
    session.commit()  # the runs must exist before a worker can pick them up
    _enqueue(session, settings, [run.id for run in job.runs])
    return JobOut.of(job)


def _variants(body: JobIn, settings: Settings) -> tuple[str, list[tuple[str, RunParams, str]]]:
    """(the job's label, (label, params, their JSON) per algorithm): each algorithm runs on
    every seed."""
    variants = []
    for name in body.algorithm_list():
        data = resolve_external(dict(body.params), settings, name)  # no command of the user's
        if name is not None:
            data["algorithm"] = name
        variants.append(_run_params(json.dumps(data, sort_keys=True)))
    algorithm = variants[0][0]
    if len(variants) > 1:  # the job's label (a column of 40 characters); each run has its own
        algorithm = "+".join(label for label, _, _ in variants)
        algorithm = algorithm if len(algorithm) <= 40 else f"{len(variants)} algorithms"
    return algorithm, variants


def _enqueue(session: Session, settings: Settings, run_ids: list[int]) -> None:
    """Send the runs to the queue; where that fails, fail them (still queued, nothing could
    take them from a queue they missed) and refuse with Unavailable."""
    try:
        send_runs(settings.redis_url, run_ids)
    except Exception as exc:
        for run_id in run_ids:
            mark_run_failed(session, run_id, f"could not enqueue: {type(exc).__name__}")
        session.commit()
        raise Unavailable(QUEUE_DOWN) from None


def list_jobs(
    session: Session,
    user: Principal,
    status: JobStatus | None = None,
    world_id: int | None = None,
    limit: int = 50,
    offset: int = 0,
) -> JobPage:
    """The user's jobs (an admin's: all), newest first, optionally by status and world."""
    stmt = select(Job)
    if not user.is_admin:
        stmt = stmt.where(Job.owner_id == user.id)
    if status is not None:
        stmt = stmt.where(Job.status == status)
    if world_id is not None:
        stmt = stmt.where(Job.world_id == world_id)
    total = session.scalar(select(func.count()).select_from(stmt.subquery())) or 0
    jobs = session.scalars(stmt.order_by(Job.id.desc()).limit(limit).offset(offset))
    return JobPage(items=[JobOut.of(j) for j in jobs], total=total, limit=limit, offset=offset)


# GET /jobs/{id} is polled: two lean column selects, no ORM objects; built once, so SQLAlchemy
# reuses their compiled form and result layout as they are (only :job_id changes).
_JOB_BY_ID = select(
    Job.id, Job.owner_id, Job.world_id, Job.status, Job.slam, Job.params, Job.created_at,
    Job.updated_at,
).where(Job.id == bindparam("job_id"))  # fmt: skip
_RUNS_OF_JOB = select(
    Run.id, Run.seed, Run.slam, Run.status, Run.outcome, Run.reason, Run.coverage, Run.b_mean_t,
    Run.b_mean_r, Run.progress,
).where(Run.job_id == bindparam("job_id")).order_by(Run.id)  # fmt: skip


def read_job(session: Session, user: Principal, job_id: int) -> JobOut:
    """A job and its runs, or NotFound (also for another owner's job)."""
    conn = session.connection()
    job = conn.execute(_JOB_BY_ID, {"job_id": job_id}).first()
    owned(user, job, "job", job_id)
    return JobOut.of(job, runs=conn.execute(_RUNS_OF_JOB, {"job_id": job_id}).all())


def job_of(session: Session, user: Principal, job_id: int) -> Job:
    """The job as stored (its runs a query away), or NotFound."""
    return owned(user, session.get(Job, job_id), "job", job_id)


def cancel_job(session: Session, user: Principal, job_id: int) -> JobOut:
    """Cancel what has not finished: queued runs never start, running ones stop at their next
    step; finished runs keep their results. Conflict for a job already over."""
    job = job_of(session, user, job_id)
    if job.status in (JobStatus.DONE, JobStatus.FAILED, JobStatus.CANCELLED):
        raise Conflict(f"job {job_id} is already {job.status}")
    for run_id in [run.id for run in job.runs]:
        cancel_run(session, run_id, "job cancelled")  # by compare-and-set: races a claim
    job.status = JobStatus.CANCELLED
    session.flush()
    return JobOut.of(job)
