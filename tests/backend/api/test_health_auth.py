"""Health checks and access rules, against a real database and a real Redis."""

from __future__ import annotations

import gc

from fastapi.testclient import TestClient
from sqlalchemy import delete

from backend.api.deps import KeyCache
from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import User
from backend.db.session import session_scope
from backend.store import hash_key
from mapqual.app import create_app
from tests.services import scratch_database


def test_healthz_and_readyz_report_database_and_broker(api):
    assert api.client.get("/healthz").json() == {"status": "ok"}
    ready = api.client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json() == {"ready": True, "database": "ok", "broker": "ok", "storage": "ok"}


def test_readyz_is_503_and_names_the_storage_when_it_cannot_be_used(db_url, tmp_path):
    (tmp_path / "runs").write_text("a file where the runs folder should be")
    settings = Settings(DATABASE_URL=db_url, MAPQUAL_RUNS_DIR=str(tmp_path / "runs"))
    with TestClient(create_app(settings)) as client:
        ready = client.get("/readyz")
    assert ready.status_code == 503
    assert ready.json()["storage"].startswith("unreachable: runs folder")
    assert "is not a folder" in ready.json()["storage"]


def test_readyz_is_503_and_names_the_broker_when_it_is_down(db_url):
    # nothing listens on port 1 of loopback
    settings = Settings(DATABASE_URL=db_url, REDIS_URL="redis://127.0.0.1:1/0")
    with TestClient(create_app(settings)) as client:
        r = client.get("/readyz")
    assert r.status_code == 503
    assert r.json()["database"] == "ok" and r.json()["broker"].startswith("unreachable")


def test_no_key_bad_key_and_bad_scheme_are_401_with_a_message(api):
    for headers in ({}, {"Authorization": "Bearer nope"}, {"Authorization": "Basic abc"}):
        r = api.client.get("/api/v1/stats", headers=headers)
        assert r.status_code == 401
        assert r.json()["detail"]


def test_key_in_header_variants_are_accepted_and_in_a_cookie_refused(api):
    key = api.keys["alice"]
    assert api.client.get("/api/v1/stats", headers={"X-API-Key": key}).status_code == 200
    # the dashboard's cookie holds a session token now (tests/backend/api/test_sessions.py)
    api.client.cookies.set("mapqual_key", key)
    assert api.client.get("/api/v1/stats").status_code == 401


def test_auth_off_must_be_explicit_and_acts_as_local(db_url, caplog):
    settings = Settings(DATABASE_URL=db_url, MAPQUAL_AUTH="off")
    with caplog.at_level("WARNING"), TestClient(create_app(settings)) as client:
        assert client.get("/api/v1/stats").status_code == 200
    assert "authentication is OFF" in caplog.text


def _delete_user(url, name):
    with session_scope(url) as s:
        s.execute(delete(User).where(User.name == name))


def test_a_deleted_users_key_is_refused_once_its_cache_entry_expires(api):
    # the cache's own clock, moved by hand: a slow database must not age the entry
    now = [1000.0]
    api.client.app.state.key_cache = KeyCache(ttl=30.0, clock=lambda: now[0])
    assert api.get("/api/v1/stats", user="bob").status_code == 200
    _delete_user(api.url, "bob")
    now[0] += 29.9
    # within the TTL the key is still trusted (no query per request)...
    assert api.get("/api/v1/stats", user="bob").status_code == 200
    now[0] += 0.2
    # ...and after it the database is asked again
    r = api.get("/api/v1/stats", user="bob")
    assert r.status_code == 401 and r.json()["detail"] == "unknown API key"


def test_an_unknown_key_is_not_cached_so_a_key_added_later_works_at_once(api):
    key = "mq_added_after_a_failed_try"
    headers = {"Authorization": f"Bearer {key}"}
    assert api.client.get("/api/v1/stats", headers=headers).status_code == 401
    with session_scope(api.url) as s:
        s.add(User(name="carol", is_admin=False, key_hash=hash_key(key)))
    assert api.client.get("/api/v1/stats", headers=headers).status_code == 200


def test_the_key_cache_is_per_app(api):
    # another app on another database must not trust a key it has never seen
    assert api.get("/api/v1/stats", user="alice").status_code == 200
    with scratch_database("mapqual_test") as other_url:
        upgrade(other_url)
        settings = Settings(DATABASE_URL=other_url, MAPQUAL_AUTH="on")
        with TestClient(create_app(settings)) as other:
            headers = {"Authorization": f"Bearer {api.keys['alice']}"}
            assert other.get("/api/v1/stats", headers=headers).status_code == 401


def test_the_heap_alive_at_the_first_start_is_kept_out_of_full_collections(api):
    # (frozen once per process: the modules, routes and mappers an app start leaves behind)
    assert gc.get_freeze_count() > 10_000
