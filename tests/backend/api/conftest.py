"""API clients on a real, migrated database, with two users and an admin."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import pytest
from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.db.session import session_scope
from backend.store import add_user
from mapqual.app import create_app
from tests.services import ensure_redis


@dataclass
class Api:
    client: TestClient
    url: str
    keys: dict[str, str]
    broker: object  # redis.Redis on the broker's database

    def get(self, path, user="alice", **kw):
        return self.client.get(path, headers=self._auth(user), **kw)

    def post(self, path, user="alice", **kw):
        headers = {**self._auth(user), **kw.pop("headers", {})}
        return self.client.post(path, headers=headers, **kw)

    def _auth(self, user):
        return {} if user is None else {"Authorization": f"Bearer {self.keys[user]}"}


@contextmanager
def serving(db_url: str, **settings: Any) -> Iterator[Api]:
    """The API on `db_url` with users alice, bob and admin, and `settings` on top."""
    # a Redis database of its own, emptied before and after, so queued messages can be counted
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/13"
    import redis

    broker = redis.Redis.from_url(redis_url)
    broker.flushdb()
    with session_scope(db_url) as s:
        keys = {
            name: add_user(s, name, is_admin=(name == "admin"))[1]
            for name in ("alice", "bob", "admin")
        }
    config = Settings(DATABASE_URL=db_url, REDIS_URL=redis_url, MAPQUAL_AUTH="on", **settings)
    with TestClient(create_app(config)) as client:
        yield Api(client, db_url, keys, broker)
    broker.flushdb()
    broker.close()


@pytest.fixture
def api(db_url):
    with serving(db_url) as served:
        yield served
