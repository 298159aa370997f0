"""Request dependencies: settings, a database session per request, the signed-in user.

Dependencies that do no I/O are `async def`, so FastAPI runs them on the event loop instead of
sending each through the thread pool; a request's blocking database work is meant to take one
trip to the pool (the hot routes open their own session inside it, see `in_session`).
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Annotated, TypeVar

from anyio import CancelScope, CapacityLimiter, to_thread
from fastapi import Depends, FastAPI, Header, HTTPException, Request, status
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend.core.config import Settings, get_settings
from backend.db.models import User
from backend.db.session import get_sessionmaker, session_scope
from backend.store import hash_key, local_user, user_for_key

API_KEY_COOKIE = "mapqual_key"
# How long [s] a valid API key is trusted without asking the database again: a user deleted
# from the database (or whose key_hash is replaced) keeps access for at most this long on each
# server process. Unknown keys are never cached, so a key added a moment ago works at once and
# a wrong key is refused every time.
KEY_CACHE_TTL = 5.0
KEY_CACHE_MAX = 10_000  # entries; past this the cache is emptied (one query per key to refill)
T = TypeVar("T")


async def settings_dep(request: Request) -> Settings:
    """The app's settings (set by `create_app`, so tests can run apps with their own)."""
    return getattr(request.app.state, "settings", None) or get_settings()


SettingsDep = Annotated[Settings, Depends(settings_dep)]


async def db_session(settings: SettingsDep) -> AsyncIterator[Session]:
    """One session per request: committed when the handler returns, rolled back on error.

    Making it does no I/O (that waits for the first query, in the handler's thread); ending it
    does, so that is one trip to a thread, shielded so a cancelled request still ends its
    transaction. That trip does not queue behind the thread pool's limit (as FastAPI ends its
    own sync dependencies): handlers filling the pool while they wait for a database
    connection would otherwise wait, until the connection pool's timeout, on the sessions
    that hold the connections."""
    session = get_sessionmaker(settings.database_url)()
    try:
        yield session
    except BaseException:
        with CancelScope(shield=True):
            await to_thread.run_sync(_end, session, False, limiter=CapacityLimiter(1))
        raise
    with CancelScope(shield=True):
        await to_thread.run_sync(_end, session, True, limiter=CapacityLimiter(1))


def _end(session: Session, commit: bool) -> None:
    try:
        if commit:
            session.commit()
        else:
            session.rollback()
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()


SessionDep = Annotated[Session, Depends(db_session)]


def in_session(settings: Settings, work: Callable[..., T], *args) -> T:
    """`work(session, *args)` in a transaction of its own (committed if it returns, rolled back
    if it raises): what an `async def` route hands to the thread pool in one trip."""
    with session_scope(settings.database_url) as session:
        return work(session, *args)


@dataclass(frozen=True)
class Principal:
    """Who a request acts for: a user's id, name and admin flag, detached from any session (so
    it can be cached between requests)."""

    id: int
    name: str
    is_admin: bool

    @classmethod
    def of(cls, user: User) -> Principal:
        return cls(id=user.id, name=user.name, is_admin=bool(user.is_admin))


class KeyCache:
    """API key hash -> Principal, each entry trusted for `ttl` seconds (one per app)."""

    def __init__(self, ttl: float = KEY_CACHE_TTL, max_entries: int = KEY_CACHE_MAX):
        self.ttl = ttl
        self.max_entries = max_entries
        self._entries: dict[str, tuple[Principal, float]] = {}

    def get(self, key_hash: str) -> Principal | None:
        entry = self._entries.get(key_hash)
        if entry is None or entry[1] < time.monotonic():
            return None
        return entry[0]

    def put(self, key_hash: str, principal: Principal) -> None:
        if len(self._entries) >= self.max_entries:
            self._entries.clear()
        self._entries[key_hash] = (principal, time.monotonic() + self.ttl)


def key_cache(app: FastAPI) -> KeyCache:
    """The app's cache of API keys seen lately (made on its first use; see KEY_CACHE_TTL)."""
    cache = getattr(app.state, "key_cache", None)
    if cache is None:
        cache = app.state.key_cache = KeyCache()
    return cache


def _key_from_request(request: Request, authorization: str | None, x_api_key: str | None) -> str:
    if authorization:
        scheme, _, token = authorization.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED, "Authorization must be 'Bearer <API key>'"
            )
        return token.strip()
    if x_api_key:
        return x_api_key.strip()
    cookie = request.cookies.get(API_KEY_COOKIE)
    if cookie:
        return cookie
    raise HTTPException(
        status.HTTP_401_UNAUTHORIZED,
        "an API key is required (Authorization: Bearer <key>); `mapqual users add NAME` makes one",
        headers={"WWW-Authenticate": "Bearer"},
    )


_LOCAL = "local"  # the cache entry of the local user (auth off); no key hash looks like it


def _lookup(session: Session, settings: Settings, key: str | None) -> Principal | None:
    if settings.auth == "off":
        return Principal.of(local_user(session))
    user = user_for_key(session, key)
    return None if user is None else Principal.of(user)


def _cache_entry(
    request: Request, settings: Settings, authorization: str | None, x_api_key: str | None
) -> tuple[str, str | None]:
    """The request's key cache entry and its key (None when auth is off); 401 without a key."""
    if settings.auth == "off":
        return _LOCAL, None
    key = _key_from_request(request, authorization, x_api_key)
    return hash_key(key), key


def _remember(request: Request, entry: str, user: Principal | None) -> Principal:
    if user is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED, "unknown API key", headers={"WWW-Authenticate": "Bearer"}
        )
    key_cache(request.app).put(entry, user)
    return user


async def current_user(
    request: Request,
    settings: SettingsDep,
    authorization: Annotated[str | None, Header()] = None,
    x_api_key: Annotated[str | None, Header()] = None,
) -> Principal:
    """The user whose key came with the request (or the local user when auth is off); a valid
    key is looked up in the database at most once per `KEY_CACHE_TTL` seconds."""
    entry, key = _cache_entry(request, settings, authorization, x_api_key)
    user = key_cache(request.app).get(entry)
    if user is None:  # a database lookup: the only case that needs a thread
        found = await run_in_threadpool(in_session, settings, _lookup, settings, key)
        user = _remember(request, entry, found)
    return user


def user_in_session(
    request: Request,
    session: Session,
    settings: Settings,
    authorization: str | None = None,
    x_api_key: str | None = None,
) -> Principal:
    """`current_user` for sync handlers that already hold a session (the sign-in page): the
    same answers and cache, the lookup made with `session`."""
    entry, key = _cache_entry(request, settings, authorization, x_api_key)
    user = key_cache(request.app).get(entry)
    if user is None:
        user = _remember(request, entry, _lookup(session, settings, key))
    return user


CurrentUser = Annotated[Principal, Depends(current_user)]


def owned(user: Principal, obj, what: str, obj_id: int):
    """`obj` if the user may see it; otherwise 404, so other owners' ids reveal nothing."""
    if obj is None or (not user.is_admin and obj.owner_id != user.id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no {what} with id {obj_id}")
    return obj
