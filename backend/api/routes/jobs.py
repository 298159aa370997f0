"""Jobs: submit runs of a world, list and read jobs, cancel one (`backend.services.jobs`)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Header, Query, Response, status
from pydantic import BaseModel
from starlette.concurrency import run_in_threadpool

from backend.api.deps import CurrentUser, IdPath, IdQuery, SessionDep, SettingsDep, in_session
from backend.core.schemas import MAX_ID, JobIn, JobOut, JobPage
from backend.services import jobs
from worker.status import JobStatus

router = APIRouter(tags=["jobs"])


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
        in_session, settings, jobs.submit, user, settings, body, idempotency_key
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
    return jobs.list_jobs(session, user, status_, world_id, limit, offset)


@router.get("/jobs/{job_id}", response_model=JobOut)
async def get_job(job_id: IdPath, user: CurrentUser, settings: SettingsDep) -> Response:
    """A job's status and its runs with their progress."""
    return json_response(await run_in_threadpool(in_session, settings, jobs.read_job, user, job_id))


@router.post("/jobs/{job_id}/cancel", response_model=JobOut)
def cancel_job(job_id: IdPath, session: SessionDep, user: CurrentUser) -> JobOut:
    """Cancel what has not finished: queued runs never start, running ones stop at their next
    step. Finished runs keep their results."""
    return jobs.cancel_job(session, user, job_id)
