"""Viewer tokens: signed for one run, one user and an expiry, refused when any of them differs
or a byte changes; access checked against the database (owner, admin, revoked); the key made
once in the database and shared by every engine and process that reaches it."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from datetime import UTC, datetime

import numpy as np
import pytest
from sqlalchemy import create_engine, func, select

from backend.core.viewer_tokens import (
    KEY_NAME,
    InvalidToken,
    app_secret,
    authorise,
    check_access,
    issue,
    sign,
    signing_key,
    verify,
)
from backend.db.models import AppSecret, Run, User
from backend.db.session import session_scope
from backend.store import add_user, create_job, save_world
from worker.world.world import World

KEY = bytes(range(32))
T0 = 1_800_000_000  # [unix s] a fixed "now"


def test_a_signed_token_verifies_for_its_run_until_it_expires():
    token = sign(KEY, 42, 7, T0 + 60)
    grant = verify(KEY, 42, token, now=T0)
    assert (grant.run_id, grant.user_id, grant.expires_at) == (42, 7, T0 + 60)
    assert verify(KEY, 42, token, now=T0 + 59.9).user_id == 7
    with pytest.raises(InvalidToken) as exc:
        verify(KEY, 42, token, now=T0 + 60)
    assert exc.value.expired
    # issue(): the expiry is now + ttl
    assert verify(KEY, 5, issue(KEY, 5, 3, 3600, now=T0), now=T0 + 3599).expires_at == T0 + 3600


def test_every_single_character_change_is_refused():
    token = sign(KEY, 42, 7, T0 + 60)
    alphabet = "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ-_."
    for i, ch in enumerate(token):
        for other in alphabet:
            if other == ch:
                continue
            bad = token[:i] + other + token[i + 1 :]
            with pytest.raises(InvalidToken):
                # a later expiry made by editing the digits must not pass either
                verify(KEY, 42, bad, now=T0)


def test_another_run_user_or_key_is_refused():
    token = sign(KEY, 42, 7, T0 + 60)
    with pytest.raises(InvalidToken):
        verify(KEY, 43, token, now=T0)  # the same token, another run
    user, exp, mac = token.split(".")
    with pytest.raises(InvalidToken):
        verify(KEY, 42, f"8.{exp}.{mac}", now=T0)  # another user's id with this signature
    with pytest.raises(InvalidToken):
        verify(bytes(32), 42, token, now=T0)  # signed with another key
    for junk in ("", "7", "7.1.x", token + "A", " " + token, token.replace(".", ":"), "0" + token):
        with pytest.raises(InvalidToken):
            verify(KEY, 42, junk, now=T0)


def _room() -> np.ndarray:
    occ = np.zeros((60, 80), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    return occ


def test_access_follows_owner_admin_and_revocation(db_url):
    with session_scope(db_url) as s:
        a, _ = add_user(s, "a")
        b, _ = add_user(s, "b")
        admin, _ = add_user(s, "root", is_admin=True)
        w = save_world(
            s, owner_id=a.id, world=World.from_array(_room(), 0.05, name="room"),
            sha256="room", source_format="image",
        )  # fmt: skip
        run_id = (
            create_job(s, owner_id=a.id, world_id=w.id, slam="odometry", params={}, seeds=[1])
            .runs[0]
            .id
        )
        ids = {"a": a.id, "b": b.id, "root": admin.id}
    key = signing_key(db_url, None)
    with session_scope(db_url) as s:
        assert authorise(s, key, run_id, issue(key, run_id, ids["a"], 60)).user_id == ids["a"]
        assert authorise(s, key, run_id, issue(key, run_id, ids["root"], 60)).run_id == run_id
        with pytest.raises(InvalidToken, match="not user"):
            authorise(s, key, run_id, issue(key, run_id, ids["b"], 60))  # signed, not hers
        with pytest.raises(InvalidToken, match="no run"):
            check_access(s, run_id + 1000, ids["a"])
    # the run changes owner: a's token stops working, b's starts
    with session_scope(db_url) as s:
        s.get_one(Run, run_id).owner_id = ids["b"]
    with session_scope(db_url) as s:
        with pytest.raises(InvalidToken):
            check_access(s, run_id, ids["a"])
        check_access(s, run_id, ids["b"])
    # a revoked user: refused, admin or not
    with session_scope(db_url) as s:
        for name in ("b", "root"):
            s.get_one(User, ids[name]).revoked_at = datetime.now(UTC)
    with session_scope(db_url) as s:
        for name in ("b", "root"):
            with pytest.raises(InvalidToken, match="revoked"):
                check_access(s, run_id, ids[name])


def test_the_secret_key_setting_overrides_the_database(db_url):
    assert signing_key(db_url, "s3cret") == signing_key("sqlite:///nowhere.db", "s3cret")
    assert signing_key(db_url, "s3cret") != signing_key(db_url, "other")
    with session_scope(db_url) as s:
        assert s.scalar(select(func.count()).select_from(AppSecret)) == 0  # nothing made


def test_concurrent_first_creation_makes_one_key_that_every_engine_reads(db_url):
    n = 8
    engines = [create_engine(db_url) for _ in range(n)]  # each its own connection pool
    start = threading.Barrier(n)
    got: list[str | BaseException] = [""] * n

    def make(i: int) -> None:
        start.wait()  # all look, find nothing, and insert at once
        try:
            got[i] = app_secret(engines[i], KEY_NAME)
        except BaseException as exc:
            got[i] = exc

    threads = [threading.Thread(target=make, args=(i,)) for i in range(n)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout=60)
    assert all(isinstance(v, str) for v in got), got
    assert len(set(got)) == 1 and len(got[0]) == 64
    with session_scope(db_url) as s:
        rows = s.scalars(select(AppSecret.value)).all()
    assert rows == [got[0]]
    # a later engine, and another process (as the API and the viewer are), read that key
    assert app_secret(create_engine(db_url), KEY_NAME) == got[0]
    code = (
        "from backend.core.viewer_tokens import signing_key; import sys; "
        "sys.stdout.write(signing_key(sys.argv[1], None).hex())"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, db_url], capture_output=True, text=True, timeout=60,
        env=dict(os.environ), check=True,
    ).stdout  # fmt: skip
    signing_key.cache_clear()  # this process's view, read afresh
    assert out == signing_key(db_url, None).hex()
    for e in engines:
        e.dispose()
