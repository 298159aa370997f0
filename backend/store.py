"""Persistence of worlds, jobs and runs: the only module that writes mapqual's tables."""

from __future__ import annotations

import dataclasses
import hashlib
import secrets
from collections.abc import Sequence
from datetime import timedelta
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from backend.db.arrays import pack_array, unpack_array
from backend.db.models import Job, Run, RunMap, RunTrajectory, User, WebSession, World, utcnow
from backend.lifecycle import (
    TransitionRefused,
    claim_run,
    fail_run,
    finish_run,
    move_into_place,
    new_attempt,
    requeue,
)
from backend.lifecycle import refresh_job_status as _refresh_job_status
from worker.report.summary import RunSummary
from worker.world.world import World as WorldModel

TRAJECTORY_KINDS = ("gt", "est")
LOCAL_USER = "local"


def hash_key(key: str) -> str:
    """The stored form of an API key (keys are 256-bit random tokens: SHA-256 suffices)."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def add_user(session: Session, name: str, is_admin: bool = False) -> tuple[User, str]:
    """A new user and their API key; the key itself is shown once and never stored."""
    if not name or len(name) > 100:
        raise ValueError("a user name is 1 to 100 characters")
    if session.scalars(select(User).where(User.name == name)).first() is not None:
        raise ValueError(f"a user named {name!r} exists already")
    key = "mq_" + secrets.token_urlsafe(32)
    user = User(name=name, is_admin=is_admin, key_hash=hash_key(key))
    session.add(user)
    session.flush()
    return user, key


def user_for_key(session: Session, key: str) -> User | None:
    """The user holding `key`, or None (also for a revoked user)."""
    stmt = select(User).where(User.key_hash == hash_key(key), User.revoked_at.is_(None))
    return session.scalars(stmt).first()


def local_user(session: Session) -> User:
    """The owner of everything made with authentication switched off (embedded use).

    Its key is random and discarded, so nobody can sign in as it over the API.
    """
    user = session.scalars(select(User).where(User.name == LOCAL_USER)).first()
    if user is None:
        user, _ = add_user(session, LOCAL_USER, is_admin=True)
    return user


def get_or_create_world(
    session: Session,
    *,
    owner_id: int,
    name: str,
    sha256: str,
    source_format: str,
    source_path: str | None,
    resolution: float,
    origin: Sequence[float],
    occ: np.ndarray,
    start_pose: Sequence[float],
    facts: dict[str, Any],
) -> World:
    """The owner's world with this content hash, or a new one: uploading twice is harmless."""
    existing = session.scalars(
        select(World).where(World.owner_id == owner_id, World.sha256 == sha256)
    ).first()
    if existing is not None:
        return existing
    world = World(
        owner_id=owner_id,
        name=name,
        sha256=sha256,
        source_format=source_format,
        source_path=source_path,
        facts=facts,
        **_geometry(resolution, origin, occ, start_pose),
    )
    session.add(world)
    session.flush()
    return world


def _geometry(
    resolution: float, origin: Sequence[float], occ: np.ndarray, start_pose: Sequence[float]
) -> dict[str, Any]:
    """The geometry columns of an analysed world (`occ (H, W) bool`, bottom row first)."""
    return {
        "resolution": float(resolution),
        "origin_x": float(origin[0]),
        "origin_y": float(origin[1]),
        "width_px": int(occ.shape[1]),
        "height_px": int(occ.shape[0]),
        "start_pose": [float(v) for v in start_pose],
        "occupancy": pack_array(np.asarray(occ, dtype=bool)),
    }


def _facts(world: WorldModel) -> dict[str, Any]:
    """A loaded world's facts as stored, with the loader's warnings."""
    facts = dataclasses.asdict(world.facts)
    facts["warnings"] = list(world.warnings)
    return facts


def save_world(
    session: Session,
    *,
    owner_id: int,
    world: WorldModel,
    sha256: str,
    source_format: str,
) -> World:
    """Store a loaded floorplan (once per owner and content hash)."""
    return get_or_create_world(
        session,
        owner_id=owner_id,
        name=world.name,
        sha256=sha256,
        source_format=source_format,
        source_path=world.source,
        resolution=world.resolution,
        origin=world.origin,
        occ=world.occ,
        start_pose=world.start_pose,
        facts=_facts(world),
    )


def world_fingerprint(world: WorldModel) -> str:
    """A content hash of a loaded world (see `World.fingerprint`)."""
    return world.fingerprint()


def world_model(row: World) -> WorldModel:
    """The pipeline's World for a stored world (grid, resolution, origin, start pose)."""
    return WorldModel.from_array(
        world_occupancy(row),
        row.resolution,
        origin=(row.origin_x, row.origin_y),
        start_pose=tuple(row.start_pose),
        name=row.name,
        n_rooms=row.facts.get("n_rooms"),
        source=row.source_path,
    )


def world_occupancy(world: World) -> np.ndarray:
    """The stored occupancy grid `(H, W) bool`, `[iy, ix]` bottom row first."""
    return unpack_array(world.occupancy)


def create_job(
    session: Session,
    *,
    owner_id: int,
    world_id: int,
    slam: str,
    params: dict[str, Any],
    seeds: Sequence[int],
    idempotency_key: str | None = None,
    broker_epoch: str | None = None,
) -> Job:
    """A queued job with one queued run per seed; every call makes new runs, never reuses old
    (except a repeated `idempotency_key` of the same owner, which returns the first job).
    `broker_epoch`: the epoch of the broker the runs are about to be sent to (see
    `backend.queue`), stamped as they are made."""
    if not seeds:
        raise ValueError("a job needs at least one seed")
    if idempotency_key is not None:
        found = session.scalars(
            select(Job).where(Job.owner_id == owner_id, Job.idempotency_key == idempotency_key)
        ).first()
        if found is not None:
            return found
    job = Job(
        owner_id=owner_id,
        world_id=world_id,
        slam=slam,
        params=params,
        status="queued",
        idempotency_key=idempotency_key,
    )
    # Runs built through the relationship: one flush inserts the job, then all runs in one
    # batched statement, and job.runs needs no second query afterwards.
    job.runs = [
        Run(
            owner_id=owner_id,
            world_id=world_id,
            seed=int(seed),
            slam=slam,
            params=params,
            broker_epoch=broker_epoch,
        )  # fmt: skip
        for seed in seeds
    ]
    session.add(job)
    session.flush()
    return job


def mark_run_started(
    session: Session, run_id: int, attempt: str | None = None, lease_s: float = 0.0
) -> Run:
    """Make `attempt` (a new one if None) the run's holder: a queued run, or a running one
    whose holder gave no sign of life for `lease_s`; raises `TransitionRefused` otherwise."""
    answer, run = claim_run(session, run_id, attempt or new_attempt(), lease_s)
    if run is None:
        raise TransitionRefused(run_id, "running", answer)
    return run


def store_run_result(
    session: Session,
    run_id: int,
    *,
    summary: RunSummary,
    t: np.ndarray,
    pose_gt: np.ndarray,
    pose_est: np.ndarray,
    map_ros: np.ndarray,
    map_resolution: float,
    map_origin: Sequence[float],
    report_dir: str | None,
    attempt: str | None = None,
    folder: Path | None = None,
) -> Run:
    """Store the result of the attempt that holds the run (None: whichever holds it) and mark
    it done, or raise `TransitionRefused` (the caller's transaction then stores nothing).

    `folder` is the attempt's report folder: renamed to `report_dir` here, after the
    compare-and-set, so that the commit that follows keeps exactly this attempt's files.
    `t (N,)`, `pose_gt`/`pose_est (N, 3)` at the same timestamps; `map_ros (H, W) int8`.
    `summary` is the report's summary.json; its headline figures are copied into columns.
    """
    doc, b, timings = summary.to_dict(), summary.relations.get("B"), summary.timings
    run = finish_run(
        session, run_id, attempt, {
            "summary": doc, "outcome": summary.outcome,
            "metrics": {k: doc[k] for k in ("relations", "ate")},
            "reason": summary.reason, "coverage": summary.coverage,
            "b_mean_t": b and b.translation.mean, "b_mean_r": b and b.rotation.mean,
            "sim_time": timings.sim_time_s, "wall_time": timings.wall_time_s,
            "report_dir": report_dir,
        },
    )  # fmt: skip
    run.trajectories.clear()  # none, unless a crash left rows of a run never marked done
    run.map = None
    session.flush()
    for kind, poses in (("gt", pose_gt), ("est", pose_est)):
        data = np.column_stack([np.asarray(t, dtype=np.float64), np.asarray(poses, np.float64)])
        run.trajectories.append(RunTrajectory(kind=kind, n_poses=len(t), data=pack_array(data)))
    run.map = RunMap(
        resolution=float(map_resolution),
        origin_x=float(map_origin[0]),
        origin_y=float(map_origin[1]),
        width=int(map_ros.shape[1]),
        height=int(map_ros.shape[0]),
        data=pack_array(np.asarray(map_ros, dtype=np.int8)),
    )
    session.flush()
    if folder is not None and report_dir is not None:
        move_into_place(folder, Path(report_dir))
    return run


def mark_run_failed(session: Session, run_id: int, error: str, attempt: str | None = None) -> bool:
    """An internal error (not a failed exploration, which is a done run with outcome failed),
    stored only while `attempt` holds the run (None: for a queued run that could not be sent);
    False when it does not: a cancelled run stays cancelled."""
    return fail_run(session, run_id, error, attempt)


def load_trajectory(session: Session, run_id: int, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """A stored trajectory as `(t (N,), poses (N, 3))`."""
    if kind not in TRAJECTORY_KINDS:
        raise ValueError(f"trajectory kind must be one of {TRAJECTORY_KINDS}, not {kind!r}")
    row = session.get(RunTrajectory, (run_id, kind))
    if row is None:
        raise LookupError(f"run {run_id} has no {kind} trajectory")
    data = unpack_array(row.data)
    return data[:, 0].copy(), data[:, 1:4].copy()


def load_map(session: Session, run_id: int) -> tuple[np.ndarray, float, tuple[float, float]]:
    """A stored final map as `(grid (H, W) int8, resolution, (origin_x, origin_y))`."""
    row = session.get(RunMap, run_id)
    if row is None:
        raise LookupError(f"run {run_id} has no map")
    return unpack_array(row.data), row.resolution, (row.origin_x, row.origin_y)


def list_runs(session: Session, limit: int = 50, world_id: int | None = None) -> list[Run]:
    """The most recent runs first."""
    stmt = select(Run).order_by(Run.id.desc()).limit(limit)
    if world_id is not None:
        stmt = stmt.where(Run.world_id == world_id)
    return list(session.scalars(stmt))


def add_job_runs(session: Session, job_id: int, seeds: Sequence[int]) -> dict[int, Run]:
    """The job's run for each seed, adding a queued run (with the job's world, algorithm and
    parameters) for any seed it lacks; a batch grown by more seeds extends its jobs this way."""
    job = session.get_one(Job, job_id)
    by_seed = {r.seed: r for r in job.runs}
    for seed in seeds:
        if int(seed) not in by_seed:
            run = Run(
                owner_id=job.owner_id, world_id=job.world_id, seed=int(seed), slam=job.slam,
                params=job.params,
            )  # fmt: skip
            job.runs.append(run)
            by_seed[int(seed)] = run
    session.flush()
    _refresh_job_status(session, job)
    return {int(s): by_seed[int(s)] for s in seeds}


def requeue_run(session: Session, run_id: int, detail: str = "requeued") -> bool:
    """Put a failed or interrupted (running) run back to queued, explicitly: a batch resumes
    or retries it. False for a run in any other state."""
    return requeue(session, run_id, detail)


def get_runs(session: Session, run_ids: Sequence[int]) -> list[Run]:
    """The runs with these ids (any order; missing ids are left out)."""
    if not run_ids:
        return []
    return list(session.scalars(select(Run).where(Run.id.in_([int(i) for i in run_ids]))))


# --- users and dashboard sessions -----------------------------------------------------------
def find_user(session: Session, name: str) -> User:
    """The user called `name`; LookupError if there is none."""
    user = session.scalars(select(User).where(User.name == name)).first()
    if user is None:
        raise LookupError(f"no user named {name!r}")
    return user


def list_users(session: Session) -> list[User]:
    """Every user, oldest first (the local user of embedded use included)."""
    return list(session.scalars(select(User).order_by(User.id)))


def revoke_user(session: Session, name: str) -> User:
    """Revoke a user's key and end their dashboard sessions at once (the API's key cache
    may trust the key for its TTL more); revoking twice keeps the first time."""
    user = find_user(session, name)
    if user.revoked_at is None:
        user.revoked_at = utcnow()
    session.execute(delete(WebSession).where(WebSession.user_id == user.id))
    session.flush()
    return user


def rotate_user_key(session: Session, name: str) -> tuple[User, str]:
    """A new API key for a user (shown once, never stored); the old key dies and their
    sessions end. A revoked user is reinstated: rotating is how a revoked user gets back in."""
    user = find_user(session, name)
    key = "mq_" + secrets.token_urlsafe(32)  # as add_user makes them
    user.key_hash = hash_key(key)
    user.revoked_at = None
    session.execute(delete(WebSession).where(WebSession.user_id == user.id))
    session.flush()
    return user, key


def create_web_session(session: Session, user_id: int, ttl_s: float) -> tuple[str, str]:
    """A new dashboard session of `ttl_s` seconds: (its token, its CSRF token). Only the
    token's hash is stored; expired sessions (anyone's: those never used again are found no
    other way) are purged on the way, through the index on their expiry."""
    now = utcnow()
    session.execute(delete(WebSession).where(WebSession.expires_at <= now))
    token, csrf = secrets.token_urlsafe(32), secrets.token_urlsafe(32)
    session.add(
        WebSession(
            token_hash=hash_key(token), user_id=user_id, csrf_token=csrf, created_at=now,
            expires_at=now + timedelta(seconds=ttl_s),
        )
    )  # fmt: skip
    session.flush()
    return token, csrf


def web_session_user(session: Session, token: str) -> tuple[User, str] | None:
    """(user, CSRF token) of a live session, or None: unknown, expired (the row is deleted
    then) or of a revoked user."""
    token_hash = hash_key(token)
    row = session.execute(
        select(User, WebSession.csrf_token, WebSession.expires_at)
        .join(WebSession, WebSession.user_id == User.id)
        .where(WebSession.token_hash == token_hash)
    ).first()
    if row is None:
        return None
    user, csrf, expires_at = row
    if expires_at <= utcnow():
        session.execute(delete(WebSession).where(WebSession.token_hash == token_hash))
        return None
    return None if user.revoked_at is not None else (user, csrf)


def delete_web_session(session: Session, token: str) -> None:
    """End a dashboard session (signing out); an unknown token is no error."""
    session.execute(delete(WebSession).where(WebSession.token_hash == hash_key(token)))


# --- worlds analysed off the request thread (pending -> ready | invalid) --------------------
def create_pending_world(
    session: Session,
    *,
    owner_id: int,
    name: str,
    sha256: str,
    source_format: str,
    source_path: str,
    upload: bytes,
    resolution: float | None,
) -> World:
    """A world whose files are stored (`upload`, packed) but not yet analysed: `pending`."""
    world = World(
        owner_id=owner_id,
        name=name,
        sha256=sha256,
        source_format=source_format,
        source_path=source_path,
        status="pending",
        upload=upload,
        upload_resolution=resolution,
        facts={},
    )
    session.add(world)
    session.flush()
    return world


def mark_world_ready(session: Session, world_id: int, world: WorldModel) -> bool:
    """Fill a pending world's geometry and facts from its analysis, drop its upload; False if
    it is no longer pending (another process finished it first: the first result stays)."""
    values = {
        "status": "ready",
        "error": None,
        "upload": None,
        "facts": _facts(world),
        **_geometry(world.resolution, world.origin, world.occ, world.start_pose),
    }
    return _finish_world(session, world_id, values)


def mark_world_invalid(session: Session, world_id: int, error: str) -> bool:
    """A pending world whose files the loader refused: `invalid`, with its one-line reason
    (the upload is dropped); False if it is no longer pending."""
    return _finish_world(session, world_id, {"status": "invalid", "error": error, "upload": None})


def _finish_world(session: Session, world_id: int, values: dict[str, Any]) -> bool:
    """Compare-and-set on `status = pending`: two analyses of one world store one result."""
    result = session.execute(
        update(World)
        .where(World.id == world_id, World.status == "pending")
        .values(**values)
        .execution_options(synchronize_session=False)
    )
    return result.rowcount == 1


def pending_world_ids(session: Session) -> list[int]:
    """Worlds still waiting for their analysis (e.g. left by a process that died), oldest first."""
    stmt = select(World.id).where(World.status == "pending").order_by(World.id)
    return list(session.scalars(stmt))


def world_upload(session: Session, world_id: int) -> tuple[bytes, float | None, str] | None:
    """(packed upload, resolution given with it, main file name) of a pending world, or None."""
    row = session.execute(
        select(World.upload, World.upload_resolution, World.source_path).where(
            World.id == world_id, World.status == "pending"
        )
    ).first()
    if row is None or row[0] is None:
        return None
    return bytes(row[0]), row[1], str(row[2])
