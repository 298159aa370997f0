"""The settings' database for shells that hold no session of their own (the CLI): migrated
to the current schema, then one transaction per block."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from sqlalchemy.orm import Session

from backend.core.config import get_settings
from backend.db.migrate import upgrade
from backend.db.session import session_scope


def migrated_url() -> str:
    """The settings' database URL, its schema brought up to date (the embedded database is
    created on first use)."""
    url = get_settings().database_url
    upgrade(url)
    return url


@contextmanager
def transaction(url: str | None = None) -> Iterator[Session]:
    """A session on `url`, by default the settings' database (migrated first): committed when
    the block ends normally, rolled back on any error."""
    with session_scope(url or migrated_url()) as session:
        yield session
