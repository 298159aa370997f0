"""Dashboard sessions and CSRF, on a real database and broker: the cookie holds a random
session token (never the key), signing out and expiry end it, every state-changing form and
cookie-authenticated API call needs the session's CSRF token, and login CSRF is refused."""

from __future__ import annotations

import io
import re
import time
from datetime import timedelta

import numpy as np
from fastapi.testclient import TestClient
from PIL import Image
from sqlalchemy import func, select, update

from backend.db.models import Job, User, WebSession, World, utcnow
from backend.db.session import session_scope
from backend.store import hash_key

TOKEN = re.compile(r'name="csrf_token" value="([^"]*)"')


def _browser(api) -> TestClient:
    # https: the session cookie is Secure, and the client (as a browser) sends it on https only
    return TestClient(api.client.app, base_url="https://testserver")


def _sign_in(api, user="alice") -> tuple[TestClient, str]:
    """A client signed in through the form, and the CSRF token its pages carry."""
    browser = _browser(api)
    r = browser.post("/login", data={"key": api.keys[user], "next": "/"}, follow_redirects=False)
    assert r.status_code == 303, r.text
    return browser, TOKEN.search(browser.get("/").text).group(1)


def _png() -> bytes:
    occ = np.zeros((60, 80), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    buf = io.BytesIO()
    Image.fromarray(np.where(occ, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _count(api, model) -> int:
    with session_scope(api.url) as s:
        return s.scalar(select(func.count()).select_from(model))


def _user_id(s, name: str) -> int:
    return s.scalars(select(User.id).where(User.name == name)).one()


def test_the_cookie_is_a_random_session_token_httponly_secure_samesite(api):
    browser = _browser(api)
    r = browser.post("/login", data={"key": api.keys["alice"]}, follow_redirects=False)
    cookies = r.headers.get_list("set-cookie")
    session = next(c for c in cookies if c.startswith("mapqual_session="))
    attrs = [a.strip().lower() for a in session.split(";")]
    token = session.split(";")[0].split("=", 1)[1]
    assert "httponly" in attrs and "secure" in attrs and "samesite=lax" in attrs
    ttl = api.client.app.state.settings.session_ttl_s
    assert f"max-age={ttl}" in attrs
    assert api.keys["alice"] not in " ".join(cookies) and len(token) >= 43  # 256 bits
    # an older version's raw-key cookie is deleted on sign-in
    assert any(c.startswith('mapqual_key=""') and "max-age=0" in c.lower() for c in cookies)
    with session_scope(api.url) as s:
        row = s.scalars(select(WebSession)).one()
        assert row.token_hash == hash_key(token) and token not in (row.token_hash, row.csrf_token)
        assert timedelta(seconds=ttl - 60) < row.expires_at - utcnow() <= timedelta(seconds=ttl)
    assert browser.get("/api/v1/stats").status_code == 200  # the pages' images and downloads


def test_after_sign_out_the_same_cookie_is_refused(api):
    browser, token = _sign_in(api)
    cookie = browser.cookies["mapqual_session"]
    r = browser.post("/logout", data={"csrf_token": token}, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/login"
    assert 'mapqual_session=""' in r.headers["set-cookie"]
    assert _count(api, WebSession) == 0
    replay = _browser(api)
    replay.cookies.set("mapqual_session", cookie)
    assert replay.get("/", follow_redirects=False).headers["location"] == "/login?next=/"
    r = replay.get("/api/v1/stats")
    assert r.status_code == 401 and "session has ended" in r.json()["detail"]


def test_an_expired_session_is_refused_and_purged(api):
    browser, _ = _sign_in(api)
    with session_scope(api.url) as s:
        s.execute(update(WebSession).values(expires_at=utcnow() - timedelta(seconds=1)))
    assert browser.get("/api/v1/stats").status_code == 401
    assert browser.get("/", follow_redirects=False).status_code == 303
    assert _count(api, WebSession) == 0
    # a session never used again is purged when anybody signs in
    _sign_in(api, "bob")
    with session_scope(api.url) as s:
        s.execute(update(WebSession).values(expires_at=utcnow() - timedelta(seconds=1)))
    _sign_in(api, "alice")
    with session_scope(api.url) as s:
        assert s.scalars(select(WebSession.user_id)).all() == [_user_id(s, "alice")]


def test_the_old_key_cookie_is_refused_everywhere(api):
    browser = _browser(api)
    browser.cookies.set("mapqual_key", api.keys["alice"])
    assert browser.get("/api/v1/stats").status_code == 401
    assert browser.get("/", follow_redirects=False).headers["location"] == "/login?next=/"


def _wait_ready(api, world_id: int, timeout_s: float = 30.0) -> None:
    """Until the uploaded world's analysis (in the app's process pool) has made it ready."""
    deadline = time.monotonic() + timeout_s
    while (status := api.get(f"/api/v1/worlds/{world_id}").json()["status"]) == "pending":
        assert time.monotonic() < deadline, f"world {world_id} still pending"
        time.sleep(0.1)
    assert status == "ready", status


def test_every_form_needs_the_sessions_csrf_token(api):
    browser, token = _sign_in(api)
    other, other_token = _sign_in(api, "bob")
    assert token != other_token  # per session
    world = (("file", ("box.png", _png(), "image/png")),)
    for bad in ({}, {"csrf_token": ""}, {"csrf_token": other_token}):
        r = browser.post("/worlds", files=world, data={"resolution": "0.05", **bad})
        assert r.status_code == 403 and "CSRF token" in r.json()["detail"]
    assert _count(api, World) == 0
    r = browser.post("/worlds", files=world, data={"resolution": "0.05", "csrf_token": token})
    assert r.status_code < 300 and "as #" in r.text, r.text
    wid = int(re.search(r"as #(\d+)", r.text).group(1))
    _wait_ready(api, wid)
    job = {"world_id": str(wid), "runs": "1", "slam": "odometry"}
    for bad in ({}, {"csrf_token": token[:-1] + "x"}):
        r = browser.post("/jobs", data={**job, **bad}, follow_redirects=False)
        assert r.status_code == 403
    assert _count(api, Job) == 0
    r = browser.post("/jobs", data={**job, "csrf_token": token}, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"].startswith("/jobs/")
    assert _count(api, Job) == 1
    assert browser.post("/logout", follow_redirects=False).status_code == 403
    assert browser.get("/api/v1/stats").status_code == 200  # still signed in
    r = browser.post("/logout", data={"csrf_token": token}, follow_redirects=False)
    assert r.status_code == 303 and browser.get("/api/v1/stats").status_code == 401


def test_the_api_reached_by_cookie_needs_the_csrf_header_and_by_key_needs_none(api):
    browser, token = _sign_in(api)
    wid = browser.post(
        "/worlds", files={"file": ("box.png", _png())}, data={"resolution": "0.05"},
        headers={"X-CSRF-Token": token},
    ).text  # fmt: skip
    wid = int(re.search(r"as #(\d+)", wid).group(1))
    _wait_ready(api, wid)
    body = {"world_id": wid, "runs": 1, "slam": "odometry"}
    r = browser.post("/api/v1/jobs", json=body)
    assert r.status_code == 403 and "X-CSRF-Token" in r.json()["detail"]
    job = browser.post("/api/v1/jobs", json=body, headers={"X-CSRF-Token": token})
    assert job.status_code == 202
    r = browser.post(f"/api/v1/jobs/{job.json()['id']}/cancel")
    assert r.status_code == 403 and _count(api, Job) == 1
    # a key header needs no CSRF token, on the API and on the pages' forms alike
    assert api.post(f"/api/v1/jobs/{job.json()['id']}/cancel").status_code == 200
    r = api.post("/jobs", data={"world_id": str(wid), "runs": "1"}, follow_redirects=False)
    assert r.status_code == 303


def test_login_posted_from_another_site_is_refused(api):
    browser = _browser(api)
    data = {"key": api.keys["alice"], "next": "/"}
    for header in ({"Origin": "https://evil.example"}, {"Origin": "null"},
                   {"Referer": "https://evil.example/form"}):  # fmt: skip
        r = browser.post("/login", data=data, headers=header, follow_redirects=False)
        assert r.status_code == 403 and "another site" in r.text
    assert _count(api, WebSession) == 0 and "mapqual_session" not in browser.cookies
    r = browser.post(
        "/login", data=data, headers={"Origin": "https://testserver"}, follow_redirects=False
    )
    assert r.status_code == 303 and _count(api, WebSession) == 1
