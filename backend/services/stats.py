"""Aggregate figures across runs: success and B errors per world (thesis Tables 6.3 to 6.5);
GET /stats and the dashboard's compare page."""

from __future__ import annotations

from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from backend.db.models import Run, World
from backend.services.access import Principal
from worker.status import RunOutcome, RunStatus


def per_world(session: Session, user: Principal) -> list[dict[str, Any]]:
    """Per world the user has runs on (an admin: every run): runs done, completed, and
    mean/std/min/max of the B errors of completed runs."""
    done = Run.status == RunStatus.DONE
    completed = Run.outcome == RunOutcome.COMPLETED
    stmt = (
        select(
            World.id,
            World.name,
            func.count(Run.id).filter(done),
            func.count(Run.id).filter(done & completed),
            func.avg(Run.b_mean_t).filter(done & completed),
            func.min(Run.b_mean_t).filter(done & completed),
            func.max(Run.b_mean_t).filter(done & completed),
            func.avg(Run.b_mean_t * Run.b_mean_t).filter(done & completed),
            func.avg(Run.b_mean_r).filter(done & completed),
            func.min(Run.b_mean_r).filter(done & completed),
            func.max(Run.b_mean_r).filter(done & completed),
            func.avg(Run.b_mean_r * Run.b_mean_r).filter(done & completed),
            func.avg(Run.coverage).filter(done),
        )
        .join(Run, Run.world_id == World.id)
        .group_by(World.id, World.name)
        .order_by(World.name)
    )
    if not user.is_admin:
        stmt = stmt.where(Run.owner_id == user.id)
    out = []
    for row in session.execute(stmt):
        wid, name, n_done, n_ok, t_mean, t_min, t_max, t_sq, r_mean, r_min, r_max, r_sq, cov = row
        out.append(
            {
                "world_id": wid,
                "world": name,
                "runs": n_done,
                "completed": n_ok,
                "success_rate": (n_ok / n_done) if n_done else None,
                "mean_coverage": cov,
                "translation": _moments(t_mean, t_sq, t_min, t_max),
                "rotation": _moments(r_mean, r_sq, r_min, r_max),
            }
        )
    return out


def _moments(
    mean: float | None, mean_sq: float | None, lo: float | None, hi: float | None
) -> dict[str, float | None]:
    """Mean, population std (from E[x^2] - E[x]^2, clipped at 0 for rounding), min, max."""
    if mean is None:
        return {"mean": None, "std": None, "min": None, "max": None}
    var = max(0.0, float(mean_sq) - float(mean) ** 2)
    return {"mean": float(mean), "std": var**0.5, "min": float(lo), "max": float(hi)}
