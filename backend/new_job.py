"""A new job and its runs stored by Core INSERT ... RETURNING (the write of every POST /jobs)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import insert
from sqlalchemy.orm import Session

from backend.db.models import Job, Run, utcnow
from worker.status import JobStatus, RunStatus


@dataclass(frozen=True)
class NewRun:
    """A run just stored by `insert_job`: queued, with no result yet."""

    id: int
    seed: int
    slam: str | None = None
    status: RunStatus = RunStatus.QUEUED
    outcome: str | None = None
    reason: str | None = None
    coverage: float | None = None
    b_mean_t: float | None = None
    b_mean_r: float | None = None
    progress: dict[str, Any] = dataclasses.field(default_factory=dict)


@dataclass(frozen=True)
class NewJob:
    """A job just stored by `insert_job`, with the columns its answer shows (as a Job has)."""

    id: int
    owner_id: int
    world_id: int
    slam: str
    params: dict[str, Any]
    created_at: datetime
    updated_at: datetime
    runs: tuple[NewRun, ...]
    status: JobStatus = JobStatus.QUEUED


# Core statements built once (SQLAlchemy caches their compiled form): no unit of work, no ORM
# objects to build and track, for the one write every POST /jobs makes.
_INSERT_JOB = insert(Job.__table__).returning(Job.__table__.c.id)
_INSERT_RUNS = insert(Run.__table__).returning(Run.__table__.c.id, sort_by_parameter_order=True)


def insert_job(
    session: Session,
    *,
    owner_id: int,
    world_id: int,
    slam: str,
    params: dict[str, Any],
    seeds: Sequence[int],
    idempotency_key: str | None = None,
    broker_epoch: str | None = None,
    variants: Sequence[tuple[str, dict[str, Any]]] | None = None,
) -> NewJob:
    """A queued job with one queued run per seed, inserted by two Core statements (the job,
    then all its runs in one INSERT ... RETURNING); the caller checked `idempotency_key`.
    `variants`: (algorithm label, params) pairs, each run on every seed (a job comparing
    algorithms); without, `slam` and `params` alone."""
    if not seeds:
        raise ValueError("a job needs at least one seed")
    conn, now = session.connection(), utcnow()
    job_id = conn.execute(
        _INSERT_JOB,
        {"owner_id": owner_id, "world_id": world_id, "slam": slam, "params": params,
         "status": JobStatus.QUEUED, "idempotency_key": idempotency_key, "created_at": now,
         "updated_at": now},
    ).scalar_one()  # fmt: skip
    rows = [
        {"owner_id": owner_id, "job_id": job_id, "world_id": world_id, "seed": int(seed),
         "slam": v_slam, "params": v_params, "broker_epoch": broker_epoch, "created_at": now}
        for v_slam, v_params in (variants or [(slam, params)])
        for seed in seeds
    ]  # fmt: skip
    run_ids = conn.execute(_INSERT_RUNS, rows).scalars().all()
    return NewJob(
        id=job_id, owner_id=owner_id, world_id=world_id, slam=slam, params=params,
        created_at=now, updated_at=now,
        runs=tuple(NewRun(id=i, seed=r["seed"], slam=r["slam"])
                   for i, r in zip(run_ids, rows, strict=True)),
    )  # fmt: skip
