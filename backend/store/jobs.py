"""The one way a job is written: a job and its runs stored by Core INSERT ... RETURNING, for
the API, the dashboard, `mapqual run` and batch alike (no unit of work, no ORM objects to
build and track: the write every POST /jobs makes)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import insert, select
from sqlalchemy.orm import Session

from backend.db.models import Job, Run, utcnow
from worker.run_params import RunParams
from worker.status import JobStatus, RunStatus

# What a run's parameters are stored from: the typed parameters, or their JSON (overrides of
# the defaults, as `RunParams.from_json` reads them).
Params = RunParams | Mapping[str, Any]


@dataclass(frozen=True)
class NewRun:
    """A run of a job as `create_job` answers it: its id, seed and algorithm, and its state
    (queued, with no result yet, when just stored)."""

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
    """A job as `create_job` answers it, with the columns its answer (`JobOut`) shows."""

    id: int
    owner_id: int
    world_id: int
    slam: str
    params: dict[str, Any]
    created_at: datetime
    updated_at: datetime
    runs: tuple[NewRun, ...]
    status: JobStatus = JobStatus.QUEUED

    @classmethod
    def of(cls, job: Job) -> NewJob:
        """A job stored earlier (the one a repeated idempotency key finds)."""
        runs = tuple(
            NewRun(id=r.id, seed=r.seed, slam=r.slam, status=r.status, outcome=r.outcome,
                   reason=r.reason, coverage=r.coverage, b_mean_t=r.b_mean_t,
                   b_mean_r=r.b_mean_r, progress=dict(r.progress or {}))
            for r in sorted(job.runs, key=lambda r: r.id)
        )  # fmt: skip
        return cls(id=job.id, owner_id=job.owner_id, world_id=job.world_id, slam=job.slam,
                   params=dict(job.params or {}), created_at=job.created_at,
                   updated_at=job.updated_at, runs=runs, status=job.status)  # fmt: skip


# Core statements built once (SQLAlchemy caches their compiled form).
_INSERT_JOB = insert(Job.__table__).returning(Job.__table__.c.id)
_INSERT_RUNS = insert(Run.__table__).returning(Run.__table__.c.id, sort_by_parameter_order=True)


def stored(params: Params) -> dict[str, Any]:
    """The JSON a run's parameters are stored as."""
    return params.to_json() if isinstance(params, RunParams) else dict(params)


def create_job(
    session: Session,
    *,
    owner_id: int,
    world_id: int,
    slam: str,
    seeds: Sequence[int],
    params: Params | None = None,
    variants: Sequence[tuple[str, Params]] | None = None,
    idempotency_key: str | None = None,
    broker_epoch: str | None = None,
    checked: bool = False,
) -> NewJob:
    """A queued job with one queued run per seed and variant, inserted by two Core statements
    (the job, then all its runs in one INSERT ... RETURNING).

    `variants`: (algorithm label, params) pairs, each run on every seed (a job comparing
    algorithms; the job keeps the first's params); without, `slam` and `params` alone. A
    repeated `idempotency_key` of the same owner returns the first job (`checked`: the caller
    looked for it already). `broker_epoch`: the epoch of the broker the runs are about to be
    sent to (see `backend.core.queue`), stamped as they are made."""
    if not seeds:
        raise ValueError("a job needs at least one seed")
    if idempotency_key is not None and not checked:
        found = session.scalars(
            select(Job).where(Job.owner_id == owner_id, Job.idempotency_key == idempotency_key)
        ).first()
        if found is not None:
            return NewJob.of(found)
    pairs = [(label, stored(p)) for label, p in variants or [(slam, params or {})]]
    job_params = pairs[0][1]
    conn, now = session.connection(), utcnow()
    job_id = conn.execute(
        _INSERT_JOB,
        {"owner_id": owner_id, "world_id": world_id, "slam": slam, "params": job_params,
         "status": JobStatus.QUEUED, "idempotency_key": idempotency_key, "created_at": now,
         "updated_at": now},
    ).scalar_one()  # fmt: skip
    rows = [
        {"owner_id": owner_id, "job_id": job_id, "world_id": world_id, "seed": int(seed),
         "slam": v_slam, "params": v_params, "broker_epoch": broker_epoch, "created_at": now}
        for v_slam, v_params in pairs
        for seed in seeds
    ]  # fmt: skip
    run_ids = conn.execute(_INSERT_RUNS, rows).scalars().all()
    return NewJob(
        id=job_id, owner_id=owner_id, world_id=world_id, slam=slam, params=job_params,
        created_at=now, updated_at=now,
        runs=tuple(NewRun(id=i, seed=r["seed"], slam=r["slam"])
                   for i, r in zip(run_ids, rows, strict=True)),
    )  # fmt: skip
