"""Per-owner quotas on runs and uploads, read from the settings; QuotaExceeded (HTTP 429).

Admins are held to the same limits: the quotas protect the service (its queue, workers and
disk), which a runaway script of an admin's fills as surely as anyone's; an operator who needs
more raises the setting the message names.
"""

from __future__ import annotations

from datetime import timedelta

from sqlalchemy import bindparam, func, select, update
from sqlalchemy.orm import Session

from backend.core.config import Settings
from backend.db.models import Run, RunEstimate, User, World, utcnow
from backend.services.errors import QuotaExceeded
from worker.explore.params import ExploreParams
from worker.run_params import RunParams
from worker.status import RunStatus

ACTIVE = (RunStatus.QUEUED, RunStatus.RUNNING)
DEFAULT_TIME_LIMIT_S = ExploreParams.time_limit  # [s] what a run without the parameter gets


# An owner's runs queued or running: how many, and the simulated seconds they may take. At most
# one run past the limit is read (:n_max): past it the answer is 429 whatever the rest, so the
# check costs O(limit), not O(runs the owner has queued). Built once: SQLAlchemy reuses its
# compiled form.
_MINE = (
    select(Run.time_limit_s)
    .where(Run.owner_id == bindparam("owner_id"), Run.status.in_(ACTIVE))
    .limit(bindparam("n_max"))
    .subquery()
)
_ACTIVE = select(
    func.count(),
    func.coalesce(func.sum(func.coalesce(_MINE.c.time_limit_s, DEFAULT_TIME_LIMIT_S)), 0.0),
).select_from(_MINE)


def check_runs(
    session: Session,
    owner_id: int,
    settings: Settings,
    n_new: int,
    params: RunParams,
    *,
    locked: bool = False,
) -> None:
    """QuotaExceeded unless `n_new` more runs with `params` keep the owner within
    `quota_active_runs` (runs queued or running at once) and `quota_sim_hours` (the simulated
    time those runs may take in all, from each run's `explore.time_limit`). Call before storing
    anything; `locked`: the transaction holds the owner's lock already (`lock_owner`, or a
    statement of its own)."""
    if not locked:
        lock_owner(session, owner_id)
    active, seconds = (
        session.connection()
        .execute(_ACTIVE, {"owner_id": owner_id, "n_max": settings.quota_active_runs + 1})
        .one()
    )
    if active + n_new > settings.quota_active_runs:
        _refuse(
            f"{active} runs queued or running and {n_new} more asked for exceed the limit "
            f"of {settings.quota_active_runs} runs at once",
            "quota_active_runs",
        )
    hours_active = float(seconds) / 3600.0
    hours_new = n_new * params.explore.time_limit / 3600.0
    if hours_active + hours_new > settings.quota_sim_hours:
        _refuse(
            f"{n_new} runs asking for {hours_new:g} simulated hours, with {hours_active:g} h "
            f"asked for by runs queued or running, exceed the limit of "
            f"{settings.quota_sim_hours:g} h",
            "quota_sim_hours",
        )


def check_upload(session: Session, owner_id: int, settings: Settings) -> None:
    """QuotaExceeded unless one more world keeps the owner within `quota_worlds` (worlds
    stored) and `quota_uploads_per_day` (worlds created in the last 24 hours)."""
    lock_owner(session, owner_id)
    since = utcnow() - timedelta(days=1)
    stored, recent = session.execute(
        select(func.count(World.id), func.count(World.id).filter(World.created_at > since)).where(
            World.owner_id == owner_id
        )
    ).one()
    if stored >= settings.quota_worlds:
        _refuse(
            f"{stored} worlds stored reach the limit of {settings.quota_worlds}", "quota_worlds"
        )
    if recent >= settings.quota_uploads_per_day:
        _refuse(
            f"{recent} worlds uploaded in the last 24 h reach the limit of "
            f"{settings.quota_uploads_per_day} per day",
            "quota_uploads_per_day",
        )


def check_estimates(
    session: Session, owner_id: int, settings: Settings, run_id: int, name: str, new_bytes: int = 0
) -> None:
    """QuotaExceeded unless one more estimate of `new_bytes` (stored trajectory) keeps the owner
    within `quota_estimates` (estimates stored) and `quota_estimate_mb` (their trajectories'
    bytes).
    The estimate it replaces (the same run and name) does not count."""
    lock_owner(session, owner_id)
    others = (RunEstimate.owner_id == owner_id) & ~(
        (RunEstimate.run_id == run_id) & (RunEstimate.name == name)
    )
    size = func.coalesce(func.sum(func.length(RunEstimate.data)), 0)
    stored, nbytes = session.execute(select(func.count(RunEstimate.id), size).where(others)).one()
    if stored + 1 > settings.quota_estimates:
        _refuse(
            f"{stored} estimates stored reach the limit of {settings.quota_estimates}",
            "quota_estimates",
        )
    limit = settings.quota_estimate_mb * 1024 * 1024
    if new_bytes and nbytes + new_bytes > limit:
        _refuse(
            f"{nbytes / 2**20:.1f} MiB of estimates stored and {new_bytes / 2**20:.1f} MiB more "
            f"exceed the limit of {settings.quota_estimate_mb:g} MiB",
            "quota_estimate_mb",
        )


def lock_owner(session: Session, user_id: int) -> None:
    """Take the owner's row until the transaction ends, so two requests of one owner at the
    same time cannot both pass on the same count."""
    if session.get_bind().dialect.name == "sqlite":
        # SQLite locks the whole database for writing, not rows: a write (that changes
        # nothing) takes that lock now, before the counts are read, and holds it to the commit,
        # so a parallel request waits (busy timeout) and then counts what this one stored
        session.execute(update(User).where(User.id == user_id).values(is_admin=User.is_admin))
        return
    # PostgreSQL, FOR NO KEY UPDATE: conflicts with itself (so one owner's checks queue) but
    # not with other transactions inserting rows that merely reference the user
    session.execute(select(User.id).where(User.id == user_id).with_for_update(key_share=True))


def _refuse(what: str, setting: str) -> None:
    env = Settings.model_fields[setting].alias
    raise QuotaExceeded(f"quota exceeded: {what} (setting {setting}, environment {env})")
