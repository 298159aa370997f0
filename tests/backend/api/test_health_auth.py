"""Health checks and access rules, against a real database and a real Redis."""

from __future__ import annotations

from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.main import create_app


def test_healthz_and_readyz_report_database_and_broker(api):
    assert api.client.get("/healthz").json() == {"status": "ok"}
    ready = api.client.get("/readyz")
    assert ready.status_code == 200
    assert ready.json() == {"ready": True, "database": "ok", "broker": "ok"}


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


def test_key_in_header_variants_and_cookie_are_accepted(api):
    key = api.keys["alice"]
    assert api.client.get("/api/v1/stats", headers={"X-API-Key": key}).status_code == 200
    api.client.cookies.set("mapqual_key", key)
    assert api.client.get("/api/v1/stats").status_code == 200


def test_auth_off_must_be_explicit_and_acts_as_local(db_url, caplog):
    settings = Settings(DATABASE_URL=db_url, MAPQUAL_AUTH="off")
    with caplog.at_level("WARNING"), TestClient(create_app(settings)) as client:
        assert client.get("/api/v1/stats").status_code == 200
    assert "authentication is OFF" in caplog.text
