"""Persistence of external estimates scored on a run (`run_estimates`): save, list, load."""

from __future__ import annotations

from typing import Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.db.arrays import pack_array, unpack_array
from backend.db.models import Run, RunEstimate

SOURCE_MAX = 200  # characters of the source name kept


def save_estimate(
    session: Session,
    run: Run,
    *,
    summary: dict[str, Any],
    t: np.ndarray,
    poses: np.ndarray,
    report_dir: str | None,
) -> RunEstimate:
    """Store a scored estimate (`summary`: `worker.export.score.EstimateScore.summary`) as an
    algorithm of `run`, replacing an earlier one of the same name."""
    name = str(summary["name"])
    row = session.scalars(
        select(RunEstimate).where(RunEstimate.run_id == run.id, RunEstimate.name == name)
    ).first()
    if row is None:
        row = RunEstimate(run_id=run.id, owner_id=run.owner_id, name=name)
        session.add(row)
    b = (summary.get("relations") or {}).get("B") or {}
    row.source = str(summary.get("source", ""))[:SOURCE_MAX]
    row.n_poses = int(len(t))
    row.metrics = {"relations": summary.get("relations", {}), "ate": summary.get("ate")}
    row.b_mean_t = (b.get("translation") or {}).get("mean")
    row.b_mean_r = (b.get("rotation") or {}).get("mean")
    row.report_dir = report_dir
    data = np.column_stack([np.asarray(t, np.float64), np.asarray(poses, np.float64)])
    row.data = pack_array(data)
    session.flush()
    return row


def list_estimates(session: Session, run_ids: list[int]) -> list[RunEstimate]:
    """The estimates of these runs, by run then name."""
    if not run_ids:
        return []
    stmt = (
        select(RunEstimate)
        .where(RunEstimate.run_id.in_([int(i) for i in run_ids]))
        .order_by(RunEstimate.run_id, RunEstimate.name)
    )
    return list(session.scalars(stmt))


def load_estimate(row: RunEstimate) -> tuple[np.ndarray, np.ndarray]:
    """A stored estimate as `(t (N,), poses (N, 3))`."""
    data = unpack_array(row.data)
    return data[:, 0].copy(), data[:, 1:4].copy()
