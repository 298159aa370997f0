"""Viewer links: a short-lived HMAC-SHA256 token for one run and one user, made by the dashboard
and checked by the viewer, keyed by MAPQUAL_SECRET_KEY or else a key kept in the database."""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
import time
from dataclasses import dataclass
from functools import lru_cache

from sqlalchemy import Engine, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.db.models import AppSecret, Run, User
from backend.db.session import get_engine

KEY_NAME = "viewer_token_key"  # the AppSecret row that holds the key when no setting gives one
# Domain separation: the same MAPQUAL_SECRET_KEY may sign other things; this key signs viewer
# tokens only, and a token is never valid as anything else.
_PURPOSE = b"mapqual viewer token v1"
# user id . expiry [unix s] . HMAC-SHA256 in unpadded base64url (43 characters); numbers
# without leading zeros, so that each token has one spelling
_TOKEN = re.compile(r"([1-9]\d{0,17})\.([1-9]\d{0,11})\.([A-Za-z0-9_-]{43})")


class InvalidToken(ValueError):
    """A token that grants nothing; `reason` says why (for the log, not for the browser)."""

    def __init__(self, reason: str, expired: bool = False):
        super().__init__(reason)
        self.reason = reason
        self.expired = expired  # authentic but too old: the browser may be told so


@dataclass(frozen=True)
class Grant:
    """What a valid token allows: `user_id` may watch `run_id` until `expires_at`."""

    run_id: int
    user_id: int
    expires_at: int  # [unix s]


def _mac(key: bytes, run_id: int, user_id: int, expires_at: int) -> bytes:
    msg = f"{run_id}:{user_id}:{expires_at}".encode()  # integers: the fields cannot run together
    return hmac.new(key, msg, hashlib.sha256).digest()


def _mac_text(key: bytes, run_id: int, user_id: int, expires_at: int) -> str:
    return base64.urlsafe_b64encode(_mac(key, run_id, user_id, expires_at)).rstrip(b"=").decode()


def sign(key: bytes, run_id: int, user_id: int, expires_at: int) -> str:
    """The token letting `user_id` watch `run_id` until `expires_at` [unix s]."""
    return f"{user_id}.{expires_at}.{_mac_text(key, run_id, user_id, expires_at)}"


def verify(key: bytes, run_id: int, token: str, now: float | None = None) -> Grant:
    """The grant `token` carries for `run_id`; InvalidToken when it is malformed, signed by
    another key or for another run or user, or expired. Says nothing of the database."""
    m = _TOKEN.fullmatch(token or "")
    if m is None:
        raise InvalidToken("no token, or not one of ours")
    user_id, expires_at = int(m.group(1)), int(m.group(2))
    # compared as text, not decoded: the last base64 character has two spare bits, and a
    # decoded comparison would accept four spellings of one signature
    if not hmac.compare_digest(m.group(3), _mac_text(key, run_id, user_id, expires_at)):
        raise InvalidToken("bad signature (another key, run or user, or altered)")
    if (time.time() if now is None else now) >= expires_at:
        raise InvalidToken("expired", expired=True)
    return Grant(run_id, user_id, expires_at)


def check_access(session: Session, run_id: int, user_id: int) -> None:
    """InvalidToken unless the run exists and the user still may see it: not revoked, and its
    owner or an admin (as the API's rule). Checked at every connection and while watching."""
    user = session.get(User, user_id)
    if user is None or user.revoked_at is not None:
        raise InvalidToken(f"user {user_id} is gone or revoked")
    owner = session.scalar(select(Run.owner_id).where(Run.id == run_id))
    if owner is None:
        raise InvalidToken(f"no run {run_id}")
    if owner != user_id and not user.is_admin:
        raise InvalidToken(f"run {run_id} is not user {user_id}'s")


def authorise(session: Session, key: bytes, run_id: int, token: str) -> Grant:
    """`verify`, then `check_access` against the database now."""
    grant = verify(key, run_id, token)
    check_access(session, run_id, grant.user_id)
    return grant


def issue(key: bytes, run_id: int, user_id: int, ttl_s: float, now: float | None = None) -> str:
    """A fresh token for a dashboard link, valid `ttl_s` seconds from now."""
    expires_at = int((time.time() if now is None else now) + ttl_s)
    return sign(key, run_id, user_id, expires_at)


def app_secret(engine: Engine, name: str) -> str:
    """The secret `name` kept in the database, made (256 random bits) on first use.

    Race-free across processes: every process inserts its own candidate and, when the primary
    key says another insert won, reads the winner's; so all of them end with the same value."""
    # three short transactions, none reading before it writes: a SQLite writer that had read
    # first would fail at once on a concurrent write instead of waiting its turn
    with Session(engine) as s:
        found = s.scalar(select(AppSecret.value).where(AppSecret.name == name))
    if found is not None:
        return found
    try:
        with Session(engine) as s, s.begin():
            s.add(AppSecret(name=name, value=secrets.token_hex(32)))
    except IntegrityError:
        pass  # another process made it first: theirs is the one
    with Session(engine) as s:
        return s.scalars(select(AppSecret.value).where(AppSecret.name == name)).one()


@lru_cache(maxsize=8)
def signing_key(database_url: str, secret_key: str | None) -> bytes:
    """The key of viewer tokens: from MAPQUAL_SECRET_KEY when set, else from the database's
    stored secret (so the API and the viewer share it with no configuration). Cached: it never
    changes once made."""
    secret = secret_key or app_secret(get_engine(database_url), KEY_NAME)
    return hmac.new(secret.encode(), _PURPOSE, hashlib.sha256).digest()
