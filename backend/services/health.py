"""Readiness: are the database, the broker and the run storage reachable. What GET /readyz
answers; each check says `ok` or why its part cannot be used."""

from __future__ import annotations

from sqlalchemy import text

from backend.core.config import Settings
from backend.db.session import get_engine


def database(settings: Settings) -> str:
    """ok, or the kind of error a `SELECT 1` met."""
    try:
        with get_engine(settings.database_url).connect() as conn:
            conn.execute(text("SELECT 1"))
    except Exception as exc:  # any driver error means not ready
        return f"unreachable: {type(exc).__name__}"
    return "ok"


def broker(settings: Settings) -> str:
    """ok, or the kind of error a PING met (1 s timeouts)."""
    try:
        import redis

        client = redis.Redis.from_url(
            settings.redis_url, socket_connect_timeout=1, socket_timeout=1
        )
        client.ping()
        client.close()
    except Exception as exc:
        return f"unreachable: {type(exc).__name__}"
    return "ok"


def storage(settings: Settings) -> str:
    """ok, or why the run storage (a local folder, an S3 bucket) cannot be used."""
    from worker.storage import StorageError

    try:
        settings.open_storage().check()
    except (StorageError, OSError) as exc:
        return f"unreachable: {exc}"
    return "ok"


def readiness(settings: Settings) -> dict[str, str]:
    """Each part's check, in the order the answer lists them."""
    return {
        "database": database(settings),
        "broker": broker(settings),
        "storage": storage(settings),
    }
