"""Fresh, migrated databases for store tests: a SQLite file and a real PostgreSQL database."""

from __future__ import annotations

import pytest

from backend.db.migrate import upgrade
from tests.services import scratch_database


@pytest.fixture(params=["sqlite", "postgresql"])
def db_url(request, tmp_path):
    """A migrated, empty database of each kind; the PostgreSQL one is dropped afterwards."""
    if request.param == "sqlite":
        url = f"sqlite:///{tmp_path / 'mapqual.db'}"
        upgrade(url)
        yield url
        return
    with scratch_database("mapqual_test") as url:
        upgrade(url)
        yield url
