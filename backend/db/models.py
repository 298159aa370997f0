"""SQLAlchemy 2 models: worlds, jobs, runs, and each run's trajectories and final map.

Trajectories and maps are stored as one compressed array blob each (see `arrays.py`), never a
row per pose: a two-hour run has 72,000 poses per trajectory.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.engine import Dialect
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship
from sqlalchemy.types import TypeDecorator

from worker.status import JobStatus, RunOutcome, RunStatus, WorldStatus


def utcnow() -> datetime:
    """Timezone-aware now, for column defaults."""
    return datetime.now(UTC)


class UtcDateTime(TypeDecorator):
    """A point in time, stored as DateTime(timezone=True) and always read back aware, in UTC.

    PostgreSQL keeps the zone; SQLite keeps none and gave naive datetimes back, so the same
    run's times read "...Z" from one database and without a zone from the other.
    """

    impl = DateTime(timezone=True)
    cache_ok = True

    def process_bind_param(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is not None and value.tzinfo is None:
            raise ValueError(f"naive datetime {value!r}: mapqual stores aware times only")
        return None if value is None else value.astimezone(UTC)

    def process_result_value(self, value: datetime | None, dialect: Dialect) -> datetime | None:
        if value is None:
            return None
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)


class _Members(dict):
    """A StrEnum's members by value, None for NULL; a value that is none raises the enum's own
    ValueError (from `__missing__`, which only a miss pays for)."""

    def __init__(self, enum: type[StrEnum]):
        super().__init__({None: None, **{m.value: m for m in enum}})
        self.enum = enum

    def __missing__(self, value: object) -> StrEnum:
        return self.enum(value)  # raises: "'x' is not a valid RunStatus"


class StatusText(TypeDecorator):
    """A status: stored as its string (VARCHAR(20), as before the enums), read back as the
    `StrEnum` member, so that rows and API answers carry the same type."""

    impl = String(20)
    cache_ok = True

    def __init__(self, enum: type[StrEnum]):
        super().__init__()
        self.enum = enum
        # stored string -> member (NULL -> None): read with the dict's own C `__getitem__`, no
        # Python call per value (GET /jobs/{id} reads seven statuses a request)
        self._members = _Members(enum)

    def process_bind_param(self, value: str | None, dialect: Dialect) -> str | None:
        return None if value is None else str(self.enum(value))

    def process_result_value(self, value: str | None, dialect: Dialect) -> StrEnum | None:
        return self._members[value]

    def result_processor(self, dialect: Dialect, coltype: object) -> Callable[[Any], Any]:
        """The lookup itself as the row processor (String has none of its own to chain)."""
        impl = self.impl_instance.result_processor(dialect, coltype)
        if impl is not None:  # a driver that converts strings itself: chain the two
            return lambda value: self._members[impl(value)]
        return self._members.__getitem__


class Base(DeclarativeBase):
    """Declarative base of every mapqual table."""

    # Named constraints, so that later migrations (SQLite batch mode included) can address them.
    metadata = MetaData(
        naming_convention={
            "ix": "ix_%(column_0_label)s",
            "uq": "uq_%(table_name)s_%(column_0_name)s",
            "ck": "ck_%(table_name)s_%(constraint_name)s",
            "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
            "pk": "pk_%(table_name)s",
        }
    )
    type_annotation_map = {dict[str, Any]: JSON, list[Any]: JSON}


class User(Base):
    """Someone who holds an API key; every world, job and run has an owner."""

    __tablename__ = "users"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    is_admin: Mapped[bool] = mapped_column(Boolean, default=False)
    # SHA-256 of the key: keys are 256-bit random tokens, so a fast hash is enough and a
    # stolen database reveals no usable key.
    key_hash: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    # A revoked user's key and sessions stop working (within the API's key cache time).
    revoked_at: Mapped[datetime | None] = mapped_column(UtcDateTime)


class WebSession(Base):
    """A dashboard sign-in: the browser holds a random token; the database its hash, the CSRF
    token of its forms and when it expires. Signing out deletes the row."""

    __tablename__ = "web_sessions"

    # SHA-256 of the session token (the cookie's value), as for API keys.
    token_hash: Mapped[str] = mapped_column(String(64), primary_key=True)
    user_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    csrf_token: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    expires_at: Mapped[datetime] = mapped_column(UtcDateTime, index=True)


class AppSecret(Base):
    """Server-side secrets made on first use (e.g. the key that signs viewer tokens), shared by
    every process that reaches the database; an environment setting overrides them."""

    __tablename__ = "app_secrets"

    name: Mapped[str] = mapped_column(String(64), primary_key=True)
    value: Mapped[str] = mapped_column(String(200))
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class World(Base):
    """A floorplan: its normalised occupancy image, resolution, origin and facts."""

    __tablename__ = "worlds"
    __table_args__ = (UniqueConstraint("owner_id", "sha256"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    name: Mapped[str] = mapped_column(String(200))
    # Content hash of the source files: the same upload twice (per owner) is the same world.
    sha256: Mapped[str] = mapped_column(String(64), index=True)
    source_format: Mapped[str] = mapped_column(String(20))  # image | yaml | stage
    source_path: Mapped[str | None] = mapped_column(Text)
    # pending (uploaded, being analysed off the request thread) | ready | invalid (see error).
    # Until ready, the geometry columns below are empty.
    status: Mapped[WorldStatus] = mapped_column(
        StatusText(WorldStatus), default=WorldStatus.READY, index=True
    )
    error: Mapped[str | None] = mapped_column(Text)
    # The uploaded files (packed by the API) and the resolution given with them, kept until
    # the analysis has read them.
    upload: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    upload_resolution: Mapped[float | None] = mapped_column(Float)  # [m/pixel]
    resolution: Mapped[float | None] = mapped_column(Float)  # [m/pixel]
    origin_x: Mapped[float | None] = mapped_column(Float)  # [m]
    origin_y: Mapped[float | None] = mapped_column(Float)  # [m]
    width_px: Mapped[int | None] = mapped_column(Integer)
    height_px: Mapped[int | None] = mapped_column(Integer)
    start_pose: Mapped[list[Any] | None] = mapped_column(JSON)  # [x, y, theta]
    facts: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # The occupancy grid as the pipeline sees it (bool [iy, ix], bottom row first), packed;
    # deferred (as are the other blobs): loaded only when read, not with every row.
    occupancy: Mapped[bytes | None] = mapped_column(LargeBinary, deferred=True)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)

    jobs: Mapped[list[Job]] = relationship(back_populates="world")


class Job(Base):
    """A request for one or more runs of one world (a batch is a job too)."""

    __tablename__ = "jobs"
    __table_args__ = (UniqueConstraint("owner_id", "idempotency_key"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    # The client's Idempotency-Key: the same key again returns this job instead of a new one.
    idempotency_key: Mapped[str | None] = mapped_column(String(200))
    world_id: Mapped[int] = mapped_column(ForeignKey("worlds.id"), index=True)
    # follows its runs (backend.store.lifecycle.refresh_job_status)
    status: Mapped[JobStatus] = mapped_column(
        StatusText(JobStatus), default=JobStatus.QUEUED, index=True
    )
    slam: Mapped[str] = mapped_column(String(40))
    params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow, onupdate=utcnow)

    world: Mapped[World] = relationship(back_populates="jobs")
    runs: Mapped[list[Run]] = relationship(back_populates="job", order_by="Run.id")


def _run_time_limit(context: Any) -> float | None:
    """A new run's simulated-time limit [s] from its params' explore.time_limit (None: the
    pipeline's default)."""
    params = context.get_current_parameters().get("params")
    explore = params.get("explore") if isinstance(params, dict) else None
    value = explore.get("time_limit") if isinstance(explore, dict) else None
    return float(value) if isinstance(value, int | float) else None


class Run(Base):
    """One simulated exploration with SLAM, and its evaluation."""

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(primary_key=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    world_id: Mapped[int] = mapped_column(ForeignKey("worlds.id"), index=True)
    seed: Mapped[int] = mapped_column(Integer)
    slam: Mapped[str] = mapped_column(String(40))
    params: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    # failed: an internal error; a failed exploration is a done run with outcome failed
    status: Mapped[RunStatus] = mapped_column(
        StatusText(RunStatus), default=RunStatus.QUEUED, index=True
    )
    # The run's own result once done: completed, or failed with a reason (collision, stuck, ...).
    outcome: Mapped[RunOutcome | None] = mapped_column(StatusText(RunOutcome))
    reason: Mapped[str | None] = mapped_column(String(40))
    coverage: Mapped[float | None] = mapped_column(Float)
    # Headline score (B relations), duplicated from `metrics` for cheap aggregate queries.
    b_mean_t: Mapped[float | None] = mapped_column(Float)  # [m]
    b_mean_r: Mapped[float | None] = mapped_column(Float)  # [rad]
    sim_time: Mapped[float | None] = mapped_column(Float)  # [s] simulated
    wall_time: Mapped[float | None] = mapped_column(Float)  # [s]
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    summary: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    progress: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    error: Mapped[str | None] = mapped_column(Text)
    report_dir: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
    started_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    finished_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    # Exactly once: the attempt that holds the run (a random id per execution), its last sign
    # of life, how many attempts started, and the broker epoch its message was sent in (a
    # broker that lost its queue has a new epoch, and the run is sent again).
    attempt: Mapped[str | None] = mapped_column(String(32))
    heartbeat_at: Mapped[datetime | None] = mapped_column(UtcDateTime)
    attempts: Mapped[int] = mapped_column(Integer, default=0)
    broker_epoch: Mapped[str | None] = mapped_column(String(32))
    # Its explore.time_limit [s], copied from `params` when the run is stored, so that the
    # per-owner quota on simulated hours is one SQL sum (backend/services/quotas.py), not a JSON
    # parse of every active run's parameters.
    time_limit_s: Mapped[float | None] = mapped_column(Float, default=_run_time_limit)

    job: Mapped[Job] = relationship(back_populates="runs")
    trajectories: Mapped[list[RunTrajectory]] = relationship(
        back_populates="run", cascade="all, delete-orphan"
    )
    map: Mapped[RunMap | None] = relationship(back_populates="run", cascade="all, delete-orphan")


class RunEvent(Base):
    """One status change of a run (its history): which attempt made it, from what, to what."""

    __tablename__ = "run_events"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    attempt: Mapped[str | None] = mapped_column(String(32))
    from_status: Mapped[RunStatus | None] = mapped_column(StatusText(RunStatus))
    to_status: Mapped[RunStatus] = mapped_column(StatusText(RunStatus))
    detail: Mapped[str | None] = mapped_column(Text)
    at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)


class RunTrajectory(Base):
    """A run's ground-truth or estimated trajectory: `(N, 4) [t, x, y, theta]` packed."""

    __tablename__ = "run_trajectories"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), primary_key=True)
    kind: Mapped[str] = mapped_column(String(8), primary_key=True)  # gt | est
    n_poses: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)

    run: Mapped[Run] = relationship(back_populates="trajectories")


class RunMap(Base):
    """A run's final SLAM map as a ROS occupancy grid (int8: -1 unknown, 0..100), packed."""

    __tablename__ = "run_maps"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), primary_key=True)
    resolution: Mapped[float] = mapped_column(Float)  # [m/cell]
    origin_x: Mapped[float] = mapped_column(Float)  # [m]
    origin_y: Mapped[float] = mapped_column(Float)  # [m]
    width: Mapped[int] = mapped_column(Integer)
    height: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)

    run: Mapped[Run] = relationship(back_populates="map")


class RunEstimate(Base):
    """An external algorithm's estimate of a run's motion, scored on the run's own relations
    (`mapqual score`, POST /runs/{id}/estimates): one more "algorithm" of that run."""

    __tablename__ = "run_estimates"
    __table_args__ = (UniqueConstraint("run_id", "name"),)

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    owner_id: Mapped[int] = mapped_column(ForeignKey("users.id"), index=True)
    name: Mapped[str] = mapped_column(String(40))  # the algorithm's name, as given by the user
    source: Mapped[str] = mapped_column(String(200))  # the file it was read from
    n_poses: Mapped[int] = mapped_column(Integer)
    # {"relations": {B, A, SM: summary}, "ate": ...}: the shape of a run's `metrics`
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    b_mean_t: Mapped[float | None] = mapped_column(Float)  # [m]
    b_mean_r: Mapped[float | None] = mapped_column(Float)  # [rad]
    report_dir: Mapped[str | None] = mapped_column(Text)
    # the estimate itself, (N, 4) [t, x, y, theta] packed as the run's trajectories are
    data: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
    created_at: Mapped[datetime] = mapped_column(UtcDateTime, default=utcnow)
