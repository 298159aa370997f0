"""Persistence of users, their API keys and their dashboard sessions."""

from __future__ import annotations

import hashlib
import secrets
from datetime import timedelta

from sqlalchemy import delete, select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.db.models import User, WebSession, utcnow

LOCAL_USER = "local"


def hash_key(key: str) -> str:
    """The stored form of an API key (keys are 256-bit random tokens: SHA-256 suffices)."""
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def add_user(session: Session, name: str, is_admin: bool = False) -> tuple[User, str]:
    """A new user and their API key; the key itself is shown once and never stored."""
    if not name or len(name) > 100:
        raise ValueError("a user name is 1 to 100 characters")
    if session.scalars(select(User).where(User.name == name)).first() is not None:
        raise ValueError(f"a user named {name!r} exists already")
    return _new_user(session, name, is_admin)


def _new_user(session: Session, name: str, is_admin: bool) -> tuple[User, str]:
    """Store a user of a name checked by the caller (IntegrityError if it is taken)."""
    key = "mq_" + secrets.token_urlsafe(32)
    user = User(name=name, is_admin=is_admin, key_hash=hash_key(key))
    session.add(user)
    session.flush()
    return user, key


def user_for_key(session: Session, key: str) -> User | None:
    """The user holding `key`, or None (also for a revoked user)."""
    stmt = select(User).where(User.key_hash == hash_key(key), User.revoked_at.is_(None))
    return session.scalars(stmt).first()


def local_user(session: Session) -> User:
    """The owner of everything made with authentication switched off (embedded use).

    Its key is random and discarded, so nobody can sign in as it over the API. Two
    processes making it at once (two `mapqual batch` started together on a new database)
    both get the one that was stored first.
    """
    mine = select(User).where(User.name == LOCAL_USER)
    user = session.scalars(mine).first()
    if user is not None:
        return user
    try:
        with session.begin_nested():
            user, _ = _new_user(session, LOCAL_USER, is_admin=True)
    except IntegrityError:  # another process stored it since the select
        return session.scalars(mine).one()
    return user


def find_user(session: Session, name: str) -> User:
    """The user called `name`; LookupError if there is none."""
    user = session.scalars(select(User).where(User.name == name)).first()
    if user is None:
        raise LookupError(f"no user named {name!r}")
    return user


def list_users(session: Session) -> list[User]:
    """Every user, oldest first (the local user of embedded use included)."""
    return list(session.scalars(select(User).order_by(User.id)))


def revoke_user(session: Session, name: str) -> User:
    """Revoke a user's key and end their dashboard sessions at once (the API's key cache
    may trust the key for its TTL more); revoking twice keeps the first time."""
    user = find_user(session, name)
    if user.revoked_at is None:
        user.revoked_at = utcnow()
    session.execute(delete(WebSession).where(WebSession.user_id == user.id))
    session.flush()
    return user


def rotate_user_key(session: Session, name: str) -> tuple[User, str]:
    """A new API key for a user (shown once, never stored); the old key dies and their
    sessions end. A revoked user is reinstated: rotating is how a revoked user gets back in."""
    user = find_user(session, name)
    key = "mq_" + secrets.token_urlsafe(32)  # as add_user makes them
    user.key_hash = hash_key(key)
    user.revoked_at = None
    session.execute(delete(WebSession).where(WebSession.user_id == user.id))
    session.flush()
    return user, key


def create_web_session(session: Session, user_id: int, ttl_s: float) -> tuple[str, str]:
    """A new dashboard session of `ttl_s` seconds: (its token, its CSRF token). Only the
    token's hash is stored; expired sessions (anyone's: those never used again are found no
    other way) are purged on the way, through the index on their expiry."""
    now = utcnow()
    session.execute(delete(WebSession).where(WebSession.expires_at <= now))
    token, csrf = secrets.token_urlsafe(32), secrets.token_urlsafe(32)
    session.add(
        WebSession(
            token_hash=hash_key(token), user_id=user_id, csrf_token=csrf, created_at=now,
            expires_at=now + timedelta(seconds=ttl_s),
        )
    )  # fmt: skip
    session.flush()
    return token, csrf


def web_session_user(session: Session, token: str) -> tuple[User, str] | None:
    """(user, CSRF token) of a live session, or None: unknown, expired (the row is deleted
    then) or of a revoked user."""
    token_hash = hash_key(token)
    row = session.execute(
        select(User, WebSession.csrf_token, WebSession.expires_at)
        .join(WebSession, WebSession.user_id == User.id)
        .where(WebSession.token_hash == token_hash)
    ).first()
    if row is None:
        return None
    user, csrf, expires_at = row
    if expires_at <= utcnow():
        session.execute(delete(WebSession).where(WebSession.token_hash == token_hash))
        return None
    return None if user.revoked_at is not None else (user, csrf)


def delete_web_session(session: Session, token: str) -> None:
    """End a dashboard session (signing out); an unknown token is no error."""
    session.execute(delete(WebSession).where(WebSession.token_hash == hash_key(token)))
