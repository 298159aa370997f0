"""Liveness and readiness: is the process up; are the database, the broker and the run
storage reachable."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import JSONResponse
from sqlalchemy import text

from backend.api.deps import SettingsDep
from backend.core.config import Settings
from backend.db.session import get_engine

router = APIRouter(tags=["health"])


@router.get("/healthz")
def healthz() -> dict[str, str]:
    """The process answers."""
    return {"status": "ok"}


@router.get("/readyz")
def readyz(settings: SettingsDep) -> JSONResponse:
    """200 when the database, the broker and the run storage all answer, else 503 saying
    which did not."""
    checks: dict[str, str] = {}
    try:
        with get_engine(settings.database_url).connect() as conn:
            conn.execute(text("SELECT 1"))
        checks["database"] = "ok"
    except Exception as exc:  # any driver error means not ready
        checks["database"] = f"unreachable: {type(exc).__name__}"
    try:
        import redis

        client = redis.Redis.from_url(
            settings.redis_url, socket_connect_timeout=1, socket_timeout=1
        )
        client.ping()
        client.close()
        checks["broker"] = "ok"
    except Exception as exc:
        checks["broker"] = f"unreachable: {type(exc).__name__}"
    checks["storage"] = _storage_check(settings)
    ready = all(v == "ok" for v in checks.values())
    return JSONResponse({"ready": ready, **checks}, status_code=200 if ready else 503)


def _storage_check(settings: Settings) -> str:
    """ok, or why the run storage (a local folder, an S3 bucket) cannot be used."""
    from worker.storage import StorageError

    try:
        settings.open_storage().check()
    except (StorageError, OSError) as exc:
        return f"unreachable: {exc}"
    return "ok"
