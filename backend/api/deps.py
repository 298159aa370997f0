"""Request dependencies: settings, a database session per request, the signed-in user.

Dependencies that do no I/O are `async def`, so FastAPI runs them on the event loop instead of
sending each through the thread pool; a request's blocking database work is meant to take one
trip to the pool (the hot routes open their own session inside it, see `in_session`).
"""

from __future__ import annotations

import hmac
import time
from collections.abc import AsyncIterator, Callable
from typing import TYPE_CHECKING, Annotated, TypeVar

from anyio import CancelScope, CapacityLimiter, to_thread
from fastapi import Depends, FastAPI, Header, HTTPException, Path, Query, Request, status
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend.core.config import Settings, get_settings
from backend.core.schemas import MAX_ID
from backend.db.session import get_sessionmaker, session_scope
from backend.services import users
from backend.services.access import Principal
from backend.services.world_analysis import WorldPool

if TYPE_CHECKING:
    from worker.predict.service import PredictionCache

# The dashboard's cookie: a random session token (the database keeps its SHA-256), never the
# API key. Sessions are looked up on every request, not cached, so signing out, `users revoke`
# and `users rotate` end them at once on every server process.
SESSION_COOKIE = "mapqual_session"
# Unsafe requests authenticated by that cookie must carry the session's CSRF token, as this
# form field (the dashboard's forms) or this header (scripts in a signed-in page).
CSRF_FIELD = "csrf_token"
CSRF_HEADER = "X-CSRF-Token"
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
# How long [s] a valid API key is trusted without asking the database again: a user deleted,
# revoked (`mapqual users revoke`) or given a new key (`mapqual users rotate`) keeps access by
# the old key for at most this long on each server process. Unknown keys are never cached, so
# a key added a moment ago works at once and a wrong key is refused every time.
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


# scope="function": the transaction ends before the response is sent. FastAPI's default for
# a dependency with `yield` ("request") ends it after, so a client following a 303 (sign-in,
# an upload, a job's submission) could ask for what the redirect points at before it was
# committed, and be told it does not exist; and a failed commit would follow a success sent.
SessionDep = Annotated[Session, Depends(db_session, scope="function")]


def in_session(settings: Settings, work: Callable[..., T], *args) -> T:
    """`work(session, *args)` in a transaction of its own (committed if it returns, rolled back
    if it raises): what an `async def` route hands to the thread pool in one trip."""
    with session_scope(settings.database_url) as session:
        return work(session, *args)


class KeyCache:
    """API key hash -> Principal, each entry trusted for `ttl` seconds (one per app)."""

    def __init__(
        self,
        ttl: float = KEY_CACHE_TTL,
        max_entries: int = KEY_CACHE_MAX,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.ttl = ttl
        self.max_entries = max_entries
        self.clock = clock
        self._entries: dict[str, tuple[Principal, float]] = {}

    def get(self, key_hash: str) -> Principal | None:
        entry = self._entries.get(key_hash)
        if entry is None or entry[1] < self.clock():
            return None
        return entry[0]

    def put(self, key_hash: str, principal: Principal) -> None:
        if len(self._entries) >= self.max_entries:
            self._entries.clear()
        self._entries[key_hash] = (principal, self.clock() + self.ttl)


def key_cache(app: FastAPI) -> KeyCache:
    """The app's cache of API keys seen lately (made on its first use; see KEY_CACHE_TTL)."""
    cache = getattr(app.state, "key_cache", None)
    if cache is None:
        cache = app.state.key_cache = KeyCache()
    return cache


def _key_from_request(authorization: str | None, x_api_key: str | None) -> str:
    if authorization:
        scheme, _, token = authorization.partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED, "Authorization must be 'Bearer <API key>'"
            )
        return token.strip()
    if x_api_key:
        return x_api_key.strip()
    raise HTTPException(
        status.HTTP_401_UNAUTHORIZED,
        "an API key is required (Authorization: Bearer <key>); `mapqual users add NAME` makes one",
        headers={"WWW-Authenticate": "Bearer"},
    )


_LOCAL = "local"  # the cache entry of the local user (auth off); no key hash looks like it


def _lookup(session: Session, settings: Settings, key: str | None) -> Principal | None:
    if settings.auth == "off":
        return users.local(session)
    return users.by_key(session, key)


def _cache_entry(
    settings: Settings, authorization: str | None, x_api_key: str | None
) -> tuple[str, str | None]:
    """The request's key cache entry and its key (None when auth is off); 401 without a key."""
    if settings.auth == "off":
        return _LOCAL, None
    key = _key_from_request(authorization, x_api_key)
    return users.key_digest(key), key


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
    key is looked up in the database at most once per `KEY_CACHE_TTL` seconds. Without a key,
    the dashboard's session cookie, checked against the database every time (and its CSRF
    token on unsafe methods: the check lives here so no route can skip it)."""
    if settings.auth == "on" and not authorization and not x_api_key:
        token = request.cookies.get(SESSION_COOKIE)
        if token:
            return await _session_user(request, settings, token)
    entry, key = _cache_entry(settings, authorization, x_api_key)
    user = key_cache(request.app).get(entry)
    if user is None:  # a database lookup: the only case that needs a thread
        found = await run_in_threadpool(in_session, settings, _lookup, settings, key)
        user = _remember(request, entry, found)
    return user


async def _session_user(request: Request, settings: Settings, token: str) -> Principal:
    """The user of a live dashboard session (401 otherwise); its CSRF token is kept on
    `request.state.csrf_token` for the pages' forms, and checked on unsafe methods."""
    found = await run_in_threadpool(in_session, settings, users.session_user, token)
    if found is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "your dashboard session has ended (signed out, expired or revoked); sign in again",
            headers={"WWW-Authenticate": "Bearer"},
        )
    user, csrf = found
    request.state.csrf_token = csrf
    if request.method not in SAFE_METHODS:
        supplied = request.headers.get(CSRF_HEADER)
        if supplied is None and _is_form(request):
            # the route's form is parsed already (FastAPI does it before the dependencies,
            # and Starlette keeps it), so this reads no body twice
            supplied = (await request.form()).get(CSRF_FIELD)
        require_csrf(supplied, csrf)
    return user


def _is_form(request: Request) -> bool:
    kind = request.headers.get("content-type", "").split(";")[0].strip().lower()
    return kind in ("application/x-www-form-urlencoded", "multipart/form-data")


def require_csrf(supplied: object, expected: str) -> None:
    """403 unless `supplied` is the session's CSRF token (compared in constant time, so the
    answer's timing tells nothing about how much of a guess was right)."""
    ok = isinstance(supplied, str) and hmac.compare_digest(
        supplied.encode("utf-8"), expected.encode("utf-8")
    )
    if not ok:
        raise HTTPException(
            status.HTTP_403_FORBIDDEN,
            "missing or wrong CSRF token: reload the page and submit the form again "
            f"(scripts send the {CSRF_HEADER} header, or an API key instead of the cookie)",
        )


CurrentUser = Annotated[Principal, Depends(current_user)]


def prediction_cache(app: FastAPI) -> PredictionCache:
    """The app's cache of world predictions (made on first use), each computed in the
    analysis sandbox (a limited process: address space, CPU and wall time)."""
    from backend.sandbox.manager import shared_sandbox
    from backend.services.world_analysis import PLAN
    from worker.errors import InputError
    from worker.predict.service import PredictionCache

    cache = getattr(app.state, "prediction_cache", None)
    if cache is None:
        settings = app.state.settings
        box = shared_sandbox(settings, "analysis")

        def compute(plan_of: Callable[[], bytes], slam: str, _model: dict) -> dict:
            facts = box.run(
                "predict", {PLAN: plan_of()}, label="the world", file=PLAN, slam=slam,
                max_pixels=settings.max_image_pixels,
            ).facts  # fmt: skip
            if not isinstance(facts.get("prediction"), dict):
                raise InputError("the world could not be analysed (a malformed result)")
            return facts["prediction"]

        workers = settings.world_workers  # as many as analyse uploads
        cache = app.state.prediction_cache = PredictionCache(workers=workers, compute=compute)
    return cache


# Ids a client sends in a path or a query, bounded as the schema's (see MAX_ID): FastAPI
# answers anything outside with 422.
IdPath = Annotated[int, Path(ge=1, le=MAX_ID, description="an id (1 to 2^31 - 1)")]
IdQuery = Annotated[int | None, Query(ge=1, le=MAX_ID, description="an id (1 to 2^31 - 1)")]


def world_pool(app: FastAPI) -> WorldPool:
    """The app's pool (made on first use, with the app's settings)."""
    pool = getattr(app.state, "world_pool", None)
    if pool is None:
        pool = app.state.world_pool = WorldPool(app.state.settings)
    return pool


def recover_pending(app: FastAPI) -> list[int]:
    """Hand every world left `pending` (by a process that died) to the pool again."""
    from backend.store import pending_world_ids

    with session_scope(app.state.settings.database_url) as s:
        ids = pending_world_ids(s)
    pool = world_pool(app)
    for world_id in ids:
        pool.submit(world_id)
    return ids
