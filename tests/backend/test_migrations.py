"""The migrations build exactly the schema the models describe, on SQLite and PostgreSQL."""

from __future__ import annotations

import multiprocessing as mp

from alembic.autogenerate import compare_metadata
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory

from backend.db.migrate import alembic_config
from backend.db.models import Base
from backend.db.session import get_engine

HEAD = ScriptDirectory.from_config(alembic_config("sqlite://")).get_current_head()


def test_migrated_schema_matches_the_models(db_url):
    with get_engine(db_url).connect() as conn:
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == []


def _upgrade_in_a_process(url: str) -> None:
    from backend.db.migrate import upgrade

    upgrade(url)


def test_concurrent_first_upgrades_of_a_fresh_database(tmp_path):
    """Two `mapqual run` started at once on a fresh machine both migrate the new database:
    one creates the schema, the others wait for it and find it at head (before, the second
    failed with a traceback: "table alembic_version already exists")."""
    from tests.services import scratch_database

    ctx = mp.get_context("spawn")
    with scratch_database("mapqual_race") as pg_url:
        for url in (f"sqlite:///{tmp_path / 'fresh.db'}", pg_url):
            procs = [ctx.Process(target=_upgrade_in_a_process, args=(url,)) for _ in range(4)]
            for p in procs:
                p.start()
            for p in procs:
                p.join(timeout=120)
            assert [p.exitcode for p in procs] == [0, 0, 0, 0], url
            with get_engine(url).connect() as conn:
                assert MigrationContext.configure(conn).get_current_heads() == (HEAD,)
                diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
            assert diff == []
            get_engine(url).dispose()
