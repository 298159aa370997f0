"""The users service: its refusals are typed (what the API maps to a status and the CLI to
exit code 2), and revoking or rotating acts on keys and dashboard sessions at once."""

from __future__ import annotations

import pytest

from backend.db.session import session_scope
from backend.services import users
from backend.services.errors import Conflict, Invalid, NotFound
from tests.backend.conftest import db_url  # noqa: F401 (the fixture)


def test_refusals_are_typed_and_store_nothing(db_url):  # noqa: F811
    with session_scope(db_url) as s:
        users.add(s, "ann")
    cases = [
        (lambda s: users.add(s, "ann"), Conflict, "a user named 'ann' exists already"),
        (lambda s: users.add(s, "x" * 101), Invalid, "a user name is 1 to 100 characters"),
        (lambda s: users.add(s, ""), Invalid, "a user name is 1 to 100 characters"),
        (lambda s: users.add(s, "local"), Invalid, "reserved"),
        (lambda s: users.revoke(s, "local"), Invalid, "reserved"),
        (lambda s: users.rotate(s, "local"), Invalid, "reserved"),
        (lambda s: users.revoke(s, "nobody"), NotFound, "no user named 'nobody'"),
        (lambda s: users.rotate(s, "nobody"), NotFound, "no user named 'nobody'"),
    ]
    for call, kind, needle in cases:
        with pytest.raises(kind) as caught, session_scope(db_url) as s:
            call(s)
        assert needle in caught.value.detail
    with session_scope(db_url) as s:
        assert [u.name for u in users.list_all(s)] == ["ann"]


def test_keys_and_sessions_follow_revoke_and_rotate(db_url):  # noqa: F811
    with session_scope(db_url) as s:
        ann, key = users.add(s, "ann", is_admin=True)
        token = users.sign_in(s, key, ttl_s=60)
    assert ann.is_admin and ann.name == "ann" and token is not None
    with session_scope(db_url) as s:
        assert users.by_key(s, key) == ann
        assert users.session_user(s, token)[0] == ann
        assert users.sign_in(s, "mq_not-a-key", ttl_s=60) is None
        users.revoke(s, "ann")
    with session_scope(db_url) as s:
        assert users.by_key(s, key) is None and users.session_user(s, token) is None
        assert users.list_all(s)[0].revoked_at is not None
        new_key = users.rotate(s, "ann")  # reinstates, with the new key only
    with session_scope(db_url) as s:
        assert users.by_key(s, key) is None and users.by_key(s, new_key) == ann
        assert users.list_all(s)[0].revoked_at is None
        token = users.sign_in(s, new_key, ttl_s=60)
        users.sign_out(s, token)
        assert users.session_user(s, token) is None


def test_the_local_user_is_one_admin_listed_with_the_others(db_url):  # noqa: F811
    with session_scope(db_url) as s:
        first = users.local(s)
        users.add(s, "ann")
    with session_scope(db_url) as s:
        assert users.local(s) == first and first.is_admin and first.name == users.LOCAL_USER
        assert [u.name for u in users.list_all(s)] == [users.LOCAL_USER, "ann"]
