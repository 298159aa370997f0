"""`mapqual users list|revoke|rotate` against a real database, seen through a running API:
a revoked or replaced key is refused once the key cache's TTL has passed, the user's
dashboard sessions end at once, and a rotated user's new key works."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from backend.api.deps import KeyCache
from backend.core.config import get_settings
from mapqual.cli import app
from tests.backend.api.conftest import api  # noqa: F401 (the fixture)
from tests.backend.conftest import db_url  # noqa: F401 (the fixture)

TTL = 0.3  # [s] the test app's key cache time (the default is 5 s)


@pytest.fixture
def cli(api, monkeypatch):  # noqa: F811 (the fixture)
    """`mapqual ...` in this process against the API's database: (exit code, stdout)."""
    monkeypatch.setenv("DATABASE_URL", api.url)
    get_settings.cache_clear()
    runner = CliRunner()

    def run(*args: str) -> tuple[int, str]:
        r = runner.invoke(app, list(args))
        return r.exit_code, r.stdout

    yield run
    get_settings.cache_clear()


def _browser(api):  # noqa: F811 (the fixture's value)
    """A client signed in through the dashboard form (https: the cookie is Secure)."""
    browser = TestClient(api.client.app, base_url="https://testserver")
    r = browser.post("/login", data={"key": api.keys["bob"]}, follow_redirects=False)
    assert r.status_code == 303
    assert browser.get("/api/v1/stats").status_code == 200
    return browser


def test_revoke_ends_sessions_at_once_and_the_key_within_the_cache_time(api, cli):  # noqa: F811
    api.client.app.state.key_cache = KeyCache(ttl=TTL)
    browser = _browser(api)
    assert api.get("/api/v1/stats", user="bob").status_code == 200  # now in the key cache
    assert cli("users", "revoke", "bob")[0] == 0
    assert browser.get("/api/v1/stats").status_code == 401  # the session: at once
    time.sleep(TTL + 0.1)
    r = api.get("/api/v1/stats", user="bob")
    assert r.status_code == 401 and r.json()["detail"] == "unknown API key"
    r = browser.post("/login", data={"key": api.keys["bob"]}, follow_redirects=False)
    assert r.status_code == 401 and "mapqual_session" not in r.headers.get("set-cookie", "")
    assert api.get("/api/v1/stats", user="alice").status_code == 200  # others unaffected


def test_rotate_kills_the_old_key_and_sessions_and_the_new_key_works(api, cli):  # noqa: F811
    # the sign-in page asks the database, never the cache: even inside the TTL the old key
    # opens no session once rotated
    api.client.app.state.key_cache = KeyCache(ttl=TTL)
    browser = _browser(api)
    assert api.get("/api/v1/stats", user="bob").status_code == 200
    code, out = cli("users", "rotate", "bob")
    assert code == 0
    new_key = out.strip().splitlines()[-1]
    assert new_key.startswith("mq_") and new_key != api.keys["bob"]
    assert browser.get("/api/v1/stats").status_code == 401
    relogin = TestClient(api.client.app, base_url="https://testserver")
    assert relogin.post("/login", data={"key": api.keys["bob"]}).status_code == 401
    time.sleep(TTL + 0.1)
    assert api.get("/api/v1/stats", user="bob").status_code == 401
    headers = {"Authorization": f"Bearer {new_key}"}
    assert api.client.get("/api/v1/stats", headers=headers).status_code == 200


def test_rotate_reinstates_a_revoked_user(api, cli):  # noqa: F811
    assert cli("users", "revoke", "bob")[0] == 0
    new_key = cli("users", "rotate", "bob")[1].strip().splitlines()[-1]
    headers = {"Authorization": f"Bearer {new_key}"}
    assert api.client.get("/api/v1/stats", headers=headers).status_code == 200


def test_list_shows_names_roles_revocations_and_no_key(api, cli):  # noqa: F811
    assert cli("users", "revoke", "bob")[0] == 0
    code, out = cli("users", "list")
    assert code == 0
    lines = out.strip().splitlines()
    assert lines[0].split() == ["name", "admin", "revoked", "created"]
    rows = {line.split()[0]: line for line in lines[1:]}
    assert set(rows) == {"alice", "bob", "admin"}
    assert re.match(r"alice\s+no\s+no\s+\d{4}-\d\d-\d\d \d\d:\d\d$", rows["alice"])
    assert re.match(r"admin\s+yes\s+no\s+", rows["admin"])
    assert re.match(r"bob\s+no\s+\d{4}-\d\d-\d\d \d\d:\d\d\s+\d{4}-", rows["bob"])
    assert not any(key in out for key in api.keys.values()) and "mq_" not in out


def test_an_unknown_or_reserved_name_is_exit_2_with_one_line(api):  # noqa: F811
    env = dict(os.environ, DATABASE_URL=api.url)
    for args, needle in ((("revoke", "nobody"), "no user named 'nobody'"),
                         (("rotate", "nobody"), "no user named 'nobody'"),
                         (("revoke", "local"), "reserved")):  # fmt: skip
        r = subprocess.run(
            [sys.executable, "-m", "mapqual", "users", *args],
            capture_output=True, text=True, env=env, timeout=120,
        )  # fmt: skip
        assert r.returncode == 2 and r.stdout == ""
        assert len(r.stderr.strip().splitlines()) == 1 and needle in r.stderr
    assert api.get("/api/v1/stats", user="bob").status_code == 200  # nothing changed
