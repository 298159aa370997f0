"""Users, their API keys and their dashboard sessions: what `mapqual users ...`, the API's key
check and the dashboard's sign-in call. Refusals are typed (a taken name is a Conflict, an
unknown one NotFound); the name of the local user of embedded use is reserved."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

from sqlalchemy.orm import Session

from backend import store
from backend.services.access import Principal
from backend.services.errors import Conflict, Invalid, NotFound

LOCAL_USER = store.LOCAL_USER
MAX_NAME = 100  # [characters] the users.name column's length


@dataclass(frozen=True)
class UserRow:
    """One user as `mapqual users list` shows them (never a key)."""

    name: str
    is_admin: bool
    revoked_at: datetime | None
    created_at: datetime


def _not_local(name: str) -> None:
    if name == LOCAL_USER:
        raise Invalid(f"the name {LOCAL_USER!r} is reserved for embedded use")


def add(session: Session, name: str, is_admin: bool = False) -> tuple[Principal, str]:
    """A new user and their API key (shown once, never stored); Invalid for a reserved or
    badly sized name, Conflict for a taken one."""
    _not_local(name)
    if not name or len(name) > MAX_NAME:
        raise Invalid(f"a user name is 1 to {MAX_NAME} characters")
    try:
        user, key = store.add_user(session, name, is_admin=is_admin)
    except ValueError as exc:  # the length is checked above: the name is taken
        raise Conflict(str(exc)) from None
    return Principal.of(user), key


def list_all(session: Session) -> list[UserRow]:
    """Every user, oldest first (the local user of embedded use included)."""
    return [
        UserRow(u.name, bool(u.is_admin), u.revoked_at, u.created_at)
        for u in store.list_users(session)
    ]


def revoke(session: Session, name: str) -> None:
    """Revoke a user: their dashboard sessions end at once, their key is refused (after the
    API's key cache time); NotFound for an unknown name."""
    _not_local(name)
    try:
        store.revoke_user(session, name)
    except LookupError as exc:
        raise NotFound(str(exc.args[0])) from None


def rotate(session: Session, name: str) -> str:
    """A user's new API key (shown once): the old one dies, sessions end, a revoked user is
    reinstated; NotFound for an unknown name."""
    _not_local(name)
    try:
        _, key = store.rotate_user_key(session, name)
    except LookupError as exc:
        raise NotFound(str(exc.args[0])) from None
    return key


def local(session: Session) -> Principal:
    """The owner of everything made with authentication off (embedded use, the CLI, batch)."""
    return Principal.of(store.local_user(session))


def key_digest(key: str) -> str:
    """The stored form of an API key (what the API's key cache is keyed by)."""
    return store.hash_key(key)


def by_key(session: Session, key: str) -> Principal | None:
    """The user holding `key`, or None (also for a revoked user)."""
    user = store.user_for_key(session, key)
    return None if user is None else Principal.of(user)


def sign_in(session: Session, key: str, ttl_s: float) -> str | None:
    """A new dashboard session's token for the holder of `key` (checked in the database, never
    a cache), or None for an unknown or revoked key."""
    user = store.user_for_key(session, key)
    if user is None:
        return None
    token, _ = store.create_web_session(session, user.id, ttl_s)
    return token


def session_user(session: Session, token: str) -> tuple[Principal, str] | None:
    """(user, CSRF token) of a live dashboard session, or None (unknown, expired, revoked)."""
    found = store.web_session_user(session, token)
    return None if found is None else (Principal.of(found[0]), found[1])


def sign_out(session: Session, token: str) -> None:
    """End a dashboard session; an unknown token is no error."""
    store.delete_web_session(session, token)
