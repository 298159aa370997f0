"""Aggregate figures across runs: success and B errors per world (`backend.services.stats`)."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, Query

from backend.api.deps import CurrentUser, SessionDep
from backend.services import stats as stats_service

router = APIRouter(tags=["stats"])


@router.get("/stats")
def stats(
    session: SessionDep,
    user: CurrentUser,
    group_by: Literal["world"] = Query("world", description="What to aggregate over."),
) -> list[dict[str, Any]]:
    """Per world: runs done, completed, and mean/std/min/max of the B errors of completed runs."""
    return stats_service.per_world(session, user)
