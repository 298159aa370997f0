"""Fresh, migrated databases for store tests: a SQLite file and a real PostgreSQL database."""

from __future__ import annotations

import uuid

import pytest
from sqlalchemy import create_engine, text

from backend.db.migrate import upgrade
from tests.services import ensure_postgres


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path):
    """A migrated, empty database of each kind; the PostgreSQL one is dropped afterwards."""
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path / 'mapqual.db'}"
        upgrade(url)
        yield url
        return
    admin_url = ensure_postgres()
    name = f"mapqual_test_{uuid.uuid4().hex[:12]}"
    admin = create_engine(admin_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = admin_url.rsplit("/", 1)[0] + f"/{name}"
    try:
        upgrade(url)
        yield url
    finally:
        from backend.db.session import get_engine

        get_engine(url).dispose()
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()
