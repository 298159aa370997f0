"""Runs: one run as its owner (or an admin) may read it, and its results read back from the
store (trajectories, the final map's files): what GET /runs/... and the dashboard's run plots
call. The embedded shells (`mapqual run|runs|score`) act as the local user and see every run:
they list runs, store a new run of a loaded world, and store scored estimates."""

from __future__ import annotations

import io
import tempfile
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend import store
from backend.db.models import Run, World
from backend.services import users
from backend.services.access import Principal, owned
from backend.services.errors import NotFound, Unavailable
from backend.store import load_map, load_trajectory
from backend.store.estimates import save_estimate
from worker.report.summary import RunSummary
from worker.status import RunStatus
from worker.storage import RunFiles, StorageError, run_files

if TYPE_CHECKING:
    from worker.run_params import RunParams
    from worker.world.world import World as WorldModel


@dataclass(frozen=True)
class RunRow:
    """One run as `mapqual runs list` shows it (fields in the order of its JSON)."""

    id: int
    job_id: int
    world: str | None
    seed: int
    slam: str
    status: str
    outcome: str | None
    reason: str | None
    coverage: float | None
    b_mean_t: float | None
    b_mean_r: float | None
    sim_time: float | None
    wall_time: float | None
    created_at: datetime | None


def run_of(session: Session, user: Principal, run_id: int) -> Run:
    """The run, or NotFound (also for another owner's)."""
    return owned(user, session.get(Run, run_id), "run", run_id)


def done_run(session: Session, user: Principal, run_id: int) -> Run:
    """The run once done, or NotFound (no such run, or no results yet)."""
    run = run_of(session, user, run_id)
    if run.status != RunStatus.DONE:
        raise NotFound(f"run {run.id} is {run.status}: no results yet")
    return run


def unreachable(run_id: int, exc: Exception) -> Unavailable:
    """The error of a done run whose files cannot be reached now."""
    return Unavailable(f"run {run_id}: its report cannot be reached ({exc})")


def report_files(run: Run) -> RunFiles:
    """The done run's report folder: NotFound when it has none, Unavailable when it cannot be
    reached."""
    if run.status != RunStatus.DONE or not run.report_dir:
        raise NotFound(f"run {run.id} has no report (yet)")
    try:
        files = run_files(run.report_dir)
        files.check()
    except (StorageError, OSError) as exc:
        raise unreachable(run.id, exc) from None
    return files


def relations_file(run: Run, kind: str) -> tuple[RunFiles, str]:
    """(the done run's report folder, the name of its relations file of `kind` A | B | SM):
    NotFound when the report has none."""
    files, name = report_files(run), f"relations_{kind}.txt"
    if not files.has(name):
        raise NotFound(f"run {run.id} has no {kind} relations")
    return files, name


def trajectory(session: Session, run: Run | int, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """A done run's trajectory `kind` (gt | est): (t (N,) [s], poses (N, 3) [x, y, theta]);
    `run` a Run or the id of one the caller was allowed to read."""
    return load_trajectory(session, run if isinstance(run, int) else run.id, kind)


def trajectory_text(t: np.ndarray, poses: np.ndarray, fmt: str) -> str:
    """A trajectory as a text file: TUM (`fmt` tum, evo reads it) or CARMEN FLASER (carmen,
    the thesis's)."""
    from worker.evaluate.trajectory import Trajectory
    from worker.evaluate.trajio import write_carmen, write_tum

    writer = write_tum if fmt == "tum" else write_carmen
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "traj.txt"
        writer(path, Trajectory(t, poses))
        return path.read_text()


def map_files(session: Session, run: Run) -> dict[str, bytes]:
    """A done run's final map from the database: map_server's PGM and YAML, and a PNG with
    its errors written on it (when the summary has relations)."""
    from worker.report.folder import error_lines
    from worker.report.plots import map_png
    from worker.slam.grid import map_server_files

    grid, res, origin = load_map(session, run.id)
    pgm, yaml = map_server_files(grid, res, origin, "map.pgm")
    buf = io.BytesIO()
    summary = RunSummary.load(run.summary)
    map_png(buf, grid, error_lines(summary) if summary and summary.relations else [])
    return {"pgm": pgm, "yaml": yaml, "png": buf.getvalue()}


def recent(session: Session, limit: int) -> list[RunRow]:
    """The newest `limit` runs of every owner, newest first."""
    rows = []
    for r in store.list_runs(session, limit=limit):
        world = session.get(World, r.world_id)
        rows.append(
            RunRow(
                id=r.id, job_id=r.job_id, world=world.name if world else None, seed=r.seed,
                slam=r.slam, status=r.status, outcome=r.outcome, reason=r.reason,
                coverage=r.coverage, b_mean_t=r.b_mean_t, b_mean_r=r.b_mean_r,
                sim_time=r.sim_time, wall_time=r.wall_time, created_at=r.created_at,
            )
        )  # fmt: skip
    return rows


def any_run(session: Session, run_id: int) -> Run:
    """Any owner's run (the embedded shells act as the local admin), or NotFound."""
    run = session.get(Run, run_id)
    if run is None:
        raise NotFound(f"no run with id {run_id}")
    return run


def report_dirs(session: Session) -> list[tuple[int, str]]:
    """(run id, report folder) of every run that has one, oldest first."""
    stmt = select(Run.id, Run.report_dir).where(Run.report_dir.is_not(None)).order_by(Run.id)
    return [(rid, d) for rid, d in session.execute(stmt)]


def create_local_run(
    session: Session, world: WorldModel, source_format: str, params: RunParams, seed: int
) -> int:
    """A job of one run, owned by the local user, for `world` (stored once per content): the
    run's id. What `mapqual run` executes in its own process."""
    owner = users.local(session).id
    row = store.save_world(
        session, owner_id=owner, world=world, sha256=store.world_fingerprint(world),
        source_format=source_format,
    )  # fmt: skip
    job = store.create_job(
        session, owner_id=owner, world_id=row.id, slam=params.algorithm, params=params,
        seeds=[seed],
    )  # fmt: skip
    return job.runs[0].id


def store_estimate(
    session: Session,
    run_id: int,
    *,
    summary: dict[str, Any],
    t: np.ndarray,
    poses: np.ndarray,
    report_dir: str | None,
) -> None:
    """Store a scored external estimate as another algorithm of run `run_id` (replacing one of
    the same name); NotFound for no such run."""
    save_estimate(
        session, any_run(session, run_id), summary=summary, t=t, poses=poses,
        report_dir=report_dir,
    )  # fmt: skip
