"""Run the Alembic migrations in `migrations/` programmatically (`mapqual db upgrade`)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: one process at a time is the user's care
    fcntl = None  # type: ignore[assignment]

from alembic import command
from alembic.config import Config

MIGRATIONS_DIR = Path(__file__).resolve().parents[2] / "migrations"


def alembic_config(url: str) -> Config:
    """An Alembic config for `url` that needs no alembic.ini on disk."""
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    # ConfigParser interpolation: a literal % in a password must be doubled.
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def upgrade(url: str, revision: str = "head") -> None:
    """Bring the database at `url` to `revision` (creating the SQLite file if needed).

    Safe to call from several processes at once (two `mapqual run` started together on a
    fresh machine): they take turns, and the later ones find the schema at `revision`. An
    SQLite file is guarded by an exclusive lock on `<file>.migrate-lock` beside it (not on
    the database file: closing another descriptor of it would drop SQLite's own locks);
    PostgreSQL by an advisory lock taken in the migration's transaction (migrations/env.py)."""
    with _sqlite_lock(url):
        command.upgrade(alembic_config(url), revision)


@contextmanager
def _sqlite_lock(url: str) -> Iterator[None]:
    path = url.removeprefix("sqlite:///") if url.startswith("sqlite:///") else ""
    if not path or path == ":memory:" or fcntl is None:
        yield
        return
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with open(f"{path}.migrate-lock", "a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
        yield
