"""Runs: one run as its owner (or an admin) may read it, and its results read back from the
store (trajectories, the final map's files). What GET /runs/... and the dashboard's run plots
call."""

from __future__ import annotations

import io

import numpy as np
from sqlalchemy.orm import Session

from backend.db.models import Run
from backend.services.access import Principal, owned
from backend.services.errors import NotFound
from backend.store import load_map, load_trajectory
from worker.report.summary import RunSummary
from worker.status import RunStatus


def run_of(session: Session, user: Principal, run_id: int) -> Run:
    """The run, or NotFound (also for another owner's)."""
    return owned(user, session.get(Run, run_id), "run", run_id)


def done_run(session: Session, user: Principal, run_id: int) -> Run:
    """The run once done, or NotFound (no such run, or no results yet)."""
    run = run_of(session, user, run_id)
    if run.status != RunStatus.DONE:
        raise NotFound(f"run {run.id} is {run.status}: no results yet")
    return run


def trajectory(session: Session, run: Run, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """A done run's trajectory `kind` (gt | est): (t (N,) [s], poses (N, 3) [x, y, theta])."""
    return load_trajectory(session, run.id, kind)


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
