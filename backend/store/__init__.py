"""Persistence of jobs and runs, and the one place to import the store from: users and
sessions live in `store_users`, worlds in `store_worlds`, re-exported here. The store modules
are the only ones that write mapqual's tables (status changes go through `lifecycle`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.db.arrays import pack_array, unpack_array
from backend.db.models import Job, Run, RunMap, RunTrajectory
from backend.store.jobs import NewJob, create_job
from backend.store.lifecycle import (
    TransitionRefused,
    claim_run,
    fail_run,
    finish_run,
    move_into_place,
    new_attempt,
    requeue,
)
from backend.store.lifecycle import refresh_job_status as _refresh_job_status
from backend.store.users import (
    LOCAL_USER,
    add_user,
    create_web_session,
    delete_web_session,
    find_user,
    hash_key,
    list_users,
    local_user,
    revoke_user,
    rotate_user_key,
    user_for_key,
    web_session_user,
)
from backend.store.worlds import (
    create_pending_world,
    get_or_create_world,
    mark_world_invalid,
    mark_world_ready,
    pending_world_ids,
    save_world,
    world_fingerprint,
    world_model,
    world_occupancy,
    world_upload,
)
from worker.status import RunStatus

__all__ = [
    "LOCAL_USER",
    "NewJob",
    "TRAJECTORY_KINDS",
    "add_job_runs",
    "add_user",
    "create_job",
    "create_pending_world",
    "create_web_session",
    "delete_web_session",
    "find_user",
    "get_or_create_world",
    "get_runs",
    "hash_key",
    "list_runs",
    "list_users",
    "load_map",
    "load_trajectory",
    "local_user",
    "mark_run_failed",
    "mark_run_started",
    "mark_world_invalid",
    "mark_world_ready",
    "pending_world_ids",
    "requeue_run",
    "revoke_user",
    "rotate_user_key",
    "save_world",
    "store_run_result",
    "user_for_key",
    "web_session_user",
    "world_fingerprint",
    "world_model",
    "world_occupancy",
    "world_upload",
]
from worker.report.summary import RunSummary

TRAJECTORY_KINDS = ("gt", "est")


def mark_run_started(
    session: Session, run_id: int, attempt: str | None = None, lease_s: float = 0.0
) -> Run:
    """Make `attempt` (a new one if None) the run's holder: a queued run, or a running one
    whose holder gave no sign of life for `lease_s`; raises `TransitionRefused` otherwise."""
    answer, run = claim_run(session, run_id, attempt or new_attempt(), lease_s)
    if run is None:
        raise TransitionRefused(run_id, RunStatus.RUNNING, answer)
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
