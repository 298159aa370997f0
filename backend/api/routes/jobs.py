"""Jobs: submit runs of a world, list and read jobs, cancel one."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Header, HTTPException, Query, status
from fastapi.responses import JSONResponse
from sqlalchemy import func, select
from sqlalchemy.orm import joinedload

from backend.api.deps import CurrentUser, SessionDep, SettingsDep, owned
from backend.db.models import Job, World
from backend.queue import enqueue_run
from backend.schemas import JobIn, JobOut, JobPage
from backend.store import create_job, mark_run_failed
from worker.pipeline import RunParams

router = APIRouter(tags=["jobs"])
JobStatus = Literal["queued", "running", "done", "failed", "cancelled"]


@router.post("/jobs", response_model=JobOut, status_code=status.HTTP_202_ACCEPTED)
def submit_job(
    body: JobIn,
    session: SessionDep,
    user: CurrentUser,
    settings: SettingsDep,
    idempotency_key: Annotated[str | None, Header(max_length=200)] = None,
) -> JSONResponse:
    """Queue one run per seed; the same Idempotency-Key again returns the same job."""
    owned(user, session.get(World, body.world_id), "world", body.world_id)
    data = dict(body.params)
    if body.slam is not None:
        data["algorithm"] = body.slam
    params = RunParams.from_json(data)  # the pipeline's own validation; InputError -> 400
    if idempotency_key is not None:
        found = session.scalars(
            select(Job).where(Job.owner_id == user.id, Job.idempotency_key == idempotency_key)
        ).first()
        if found is not None:
            return JSONResponse(JobOut.of(found).model_dump(mode="json"), status_code=202)
    job = create_job(
        session,
        owner_id=user.id,
        world_id=body.world_id,
        slam=params.algorithm,
        params=params.to_json(),
        seeds=body.seed_list(),
        idempotency_key=idempotency_key,
    )
    session.commit()  # the runs must exist before a worker can pick them up
    try:
        for run in job.runs:
            enqueue_run(settings.redis_url, run.id)
    except Exception as exc:
        for run in job.runs:
            if run.status == "queued":
                mark_run_failed(session, run.id, f"could not enqueue: {type(exc).__name__}")
        session.commit()
        raise HTTPException(
            status.HTTP_503_SERVICE_UNAVAILABLE, "the job queue is unreachable; try again later"
        ) from None
    return JSONResponse(JobOut.of(job).model_dump(mode="json"), status_code=202)


@router.get("/jobs", response_model=JobPage)
def list_jobs(
    session: SessionDep,
    user: CurrentUser,
    status_: Annotated[JobStatus | None, Query(alias="status")] = None,
    world_id: int | None = None,
    limit: Annotated[int, Query(ge=1, le=200)] = 50,
    offset: Annotated[int, Query(ge=0)] = 0,
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


@router.get("/jobs/{job_id}", response_model=JobOut)
def get_job(job_id: int, session: SessionDep, user: CurrentUser) -> JobOut:
    """A job's status and its runs with their progress."""
    # the job and its runs in one query (a polled endpoint: round trips are its cost)
    job = session.get(Job, job_id, options=[joinedload(Job.runs)])
    return JobOut.of(owned(user, job, "job", job_id))


@router.post("/jobs/{job_id}/cancel", response_model=JobOut)
def cancel_job(job_id: int, session: SessionDep, user: CurrentUser) -> JobOut:
    """Cancel what has not finished: queued runs never start, running ones stop at their next
    step. Finished runs keep their results."""
    job = owned(user, session.get(Job, job_id), "job", job_id)
    if job.status in ("done", "failed", "cancelled"):
        raise HTTPException(status.HTTP_409_CONFLICT, f"job {job_id} is already {job.status}")
    for run in job.runs:
        if run.status in ("queued", "running"):
            run.status = "cancelled"
    job.status = "cancelled"
    session.flush()
    return JobOut.of(job)
