"""One build at a time of a thing named by a string, across threads, processes and hosts:
a PostgreSQL advisory lock when the database is PostgreSQL (every API process on every host
shares it), else a file lock on this host (the embedded SQLite case is one host)."""

from __future__ import annotations

import fcntl
import hashlib
import tempfile
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import text

from backend.db.session import get_engine

_THREAD_LOCKS: dict[str, threading.Lock] = {}
_GUARD = threading.Lock()


def _lock_id(name: str) -> int:
    """A signed 64-bit id of `name` (what pg_advisory_lock takes)."""
    return int.from_bytes(
        hashlib.blake2b(name.encode(), digest_size=8).digest(), "big", signed=True
    )


@contextmanager
def single_flight(database_url: str, name: str) -> Iterator[None]:
    """Hold the lock `name` for the block; others asking for it wait until it is released."""
    with _GUARD:
        local = _THREAD_LOCKS.setdefault(name, threading.Lock())
    with local:  # threads of this process queue here, so one holds the shared lock at a time
        if database_url.startswith("postgresql"):
            with get_engine(database_url).connect() as conn:
                conn.execute(text("SELECT pg_advisory_lock(:k)"), {"k": _lock_id(name)})
                try:
                    yield
                finally:
                    conn.execute(text("SELECT pg_advisory_unlock(:k)"), {"k": _lock_id(name)})
                    conn.commit()
            return
        folder = Path(tempfile.gettempdir()) / "mapqual-locks"
        folder.mkdir(exist_ok=True)
        with (folder / f"{_lock_id(name) & (2**63 - 1):x}.lock").open("a") as f:
            fcntl.flock(f, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(f, fcntl.LOCK_UN)
