"""Jobs: submit runs of a world, list and read jobs, cancel one."""

from __future__ import annotations

import json
from functools import lru_cache
from typing import Annotated

from fastapi import APIRouter, Header, HTTPException, Query, Response, status
from pydantic import BaseModel
from sqlalchemy import bindparam, func, select
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend import quotas
from backend.api.deps import (
    CurrentUser,
    IdPath,
    IdQuery,
    Principal,
    SessionDep,
    SettingsDep,
    in_session,
    owned,
)
from backend.core.config import Settings
from backend.db.models import Job, Run, User, World
from backend.external_slam import resolve_external
from backend.lifecycle import cancel_run
from backend.new_job import insert_job
from backend.queue import EPOCH_MAX_AGE_S, broker_epoch, send_runs
from backend.schemas import MAX_ID, JobIn, JobOut, JobPage
from backend.store import mark_run_failed
from worker.run_params import RunParams  # light: no numba in the API process
from worker.slam import registry
from worker.status import JobStatus, WorldStatus

router = APIRouter(tags=["jobs"])


@lru_cache(maxsize=256)
def _run_params(overrides_json: str) -> tuple[str, str]:
    """(algorithm's label, RunParams JSON) for the overrides: validated by the pipeline's own
    rules (InputError -> 400), once per distinct set of overrides; the label of an external
    program is external:NAME."""
    params = RunParams.from_json(json.loads(overrides_json))
    return registry.label(params.algorithm, params.slam), json.dumps(params.to_json())


_WORLD_OWNER = select(World.owner_id, World.status).where(World.id == bindparam("world_id"))
# The same, taking the submitting user's row as the quota check needs (PostgreSQL: FOR NO KEY
# UPDATE OF users, see `quotas.lock_owner`): one statement where the check would add another.
_WORLD_OWNER_LOCKING_USER = (
    select(World.owner_id, World.status)
    .join(User, User.id == bindparam("user_id"))
    .where(World.id == bindparam("world_id"))
    .with_for_update(of=User, key_share=True)
)


def _queue_down() -> HTTPException:
    return HTTPException(
        status.HTTP_503_SERVICE_UNAVAILABLE, "the job queue is unreachable; try again later"
    )


def submit(
    session: Session,
    user: Principal,
    settings: Settings,
    body: JobIn,
    idempotency_key: str | None,
) -> JobOut:
    """Store a job of one queued run per seed and queue its runs (the work of POST /jobs, also
    used by the dashboard's form)."""
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
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            f"world {body.world_id} is {world.status}, not ready: runs need an analysed world",
        )
    algorithm, params_json, variants = _variants(body, settings)
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
        raise _queue_down() from None
    n_new, run_params = len(body.seed_list()) * len(variants), json.loads(params_json)
    quotas.check_runs(session, user.id, settings, n_new, run_params, locked=locked)
    job = insert_job(
        session,
        owner_id=user.id,
        world_id=body.world_id,
        slam=algorithm,
        params=run_params,
        seeds=body.seed_list(),
        idempotency_key=idempotency_key,
        broker_epoch=epoch,
        variants=[(label, json.loads(p)) for label, p in variants] if len(variants) > 1 else None,
    )
    session.commit()  # the runs must exist before a worker can pick them up
    _enqueue(session, settings, job)
    return JobOut.of(job)


def _variants(body: JobIn, settings: Settings) -> tuple[str, str, list[tuple[str, str]]]:
    """(the job's label, the first variant's params JSON, (label, params JSON) per algorithm):
    each algorithm runs on every seed."""
    variants = []
    for name in body.algorithm_list():
        data = resolve_external(dict(body.params), settings, name)  # no command of the user's
        if name is not None:
            data["algorithm"] = name
        variants.append(_run_params(json.dumps(data, sort_keys=True)))
    algorithm, params_json = variants[0]
    if len(variants) > 1:  # the job's label (a column of 40 characters); each run has its own
        algorithm = "+".join(label for label, _ in variants)
        algorithm = algorithm if len(algorithm) <= 40 else f"{len(variants)} algorithms"
    return algorithm, params_json, variants


def _enqueue(session: Session, settings: Settings, job: Job) -> None:
    """Send the job's runs to the queue; where that fails, fail them (still queued, nothing could
    take them from a queue they missed) and answer 503."""
    try:
        send_runs(settings.redis_url, [run.id for run in job.runs])
    except Exception as exc:
        for run in job.runs:
            mark_run_failed(session, run.id, f"could not enqueue: {type(exc).__name__}")
        session.commit()
        raise _queue_down() from None


def json_response(model: BaseModel, status_code: int = 200) -> Response:
    """`model` serialised once by its own pydantic serializer. A route that declares
    `response_model` and returns a Response skips FastAPI's second validation and encoding
    (the model still documents the answer in OpenAPI)."""
    return Response(model.model_dump_json(), status_code, media_type="application/json")


@router.post("/jobs", response_model=JobOut, status_code=status.HTTP_202_ACCEPTED)
async def submit_job(
    body: JobIn,
    user: CurrentUser,
    settings: SettingsDep,
    idempotency_key: Annotated[str | None, Header(max_length=200)] = None,
) -> Response:
    """Queue one run per seed; the same Idempotency-Key again returns the same job."""
    job = await run_in_threadpool(
        in_session, settings, submit, user, settings, body, idempotency_key
    )
    return json_response(job, status.HTTP_202_ACCEPTED)


@router.get("/jobs", response_model=JobPage)
def list_jobs(
    session: SessionDep,
    user: CurrentUser,
    status_: Annotated[JobStatus | None, Query(alias="status")] = None,
    world_id: IdQuery = None,
    limit: Annotated[int, Query(ge=1, le=200)] = 50,
    offset: Annotated[int, Query(ge=0, le=MAX_ID)] = 0,
) -> JobPage:
    """Your jobs, newest first, optionally filtered by status and world."""
    stmt = select(Job)
    if not user.is_admin:
        stmt = stmt.where(Job.owner_id == user.id)
    if status_ is not None:
        stmt = stmt.where(Job.status == status_)
    if world_id is not None:
        stmt = stmt.where(Job.world_id == world_id)
    total = session.scalar(select(func.count()).select_from(stmt.subquery()))
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
    """A job and its runs as JobOut, or 404 (also for another owner's job)."""
    conn = session.connection()
    job = conn.execute(_JOB_BY_ID, {"job_id": job_id}).first()
    owned(user, job, "job", job_id)
    return JobOut.of(job, runs=conn.execute(_RUNS_OF_JOB, {"job_id": job_id}).all())


@router.get("/jobs/{job_id}", response_model=JobOut)
async def get_job(job_id: IdPath, user: CurrentUser, settings: SettingsDep) -> Response:
    """A job's status and its runs with their progress."""
    return json_response(await run_in_threadpool(in_session, settings, read_job, user, job_id))


@router.post("/jobs/{job_id}/cancel", response_model=JobOut)
def cancel_job(job_id: IdPath, session: SessionDep, user: CurrentUser) -> JobOut:
    """Cancel what has not finished: queued runs never start, running ones stop at their next
    step. Finished runs keep their results."""
    job = owned(user, session.get(Job, job_id), "job", job_id)
    if job.status in (JobStatus.DONE, JobStatus.FAILED, JobStatus.CANCELLED):
        raise HTTPException(status.HTTP_409_CONFLICT, f"job {job_id} is already {job.status}")
    for run_id in [run.id for run in job.runs]:
        cancel_run(session, run_id, "job cancelled")  # by compare-and-set: races a claim
    job.status = JobStatus.CANCELLED
    session.flush()
    return JobOut.of(job)
