"""Request dependencies: settings, a database session per request, the signed-in user."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Header, HTTPException, Request, status
from sqlalchemy.orm import Session

from backend.core.config import Settings, get_settings
from backend.db.models import User
from backend.db.session import get_sessionmaker
from backend.store import local_user, user_for_key

API_KEY_COOKIE = "mapqual_key"


def settings_dep(request: Request) -> Settings:
    """The app's settings (set by `create_app`, so tests can run apps with their own)."""
    return getattr(request.app.state, "settings", None) or get_settings()


SettingsDep = Annotated[Settings, Depends(settings_dep)]


def db_session(settings: SettingsDep) -> Iterator[Session]:
    """One session per request: committed when the handler returns, rolled back on error."""
    session = get_sessionmaker(settings.database_url)()
    try:
        yield session
        session.commit()
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()


SessionDep = Annotated[Session, Depends(db_session)]


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


def current_user(
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    authorization: Annotated[str | None, Header()] = None,
    x_api_key: Annotated[str | None, Header()] = None,
) -> User:
    """The user whose key came with the request (or the local user when auth is off)."""
    if settings.auth == "off":
        return local_user(session)
    key = _key_from_request(request, authorization, x_api_key)
    user = user_for_key(session, key)
    if user is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED, "unknown API key", headers={"WWW-Authenticate": "Bearer"}
        )
    return user


CurrentUser = Annotated[User, Depends(current_user)]


def owned(user: User, obj, what: str, obj_id: int):
    """`obj` if the user may see it; otherwise 404, so other owners' ids reveal nothing."""
    if obj is None or (not user.is_admin and obj.owner_id != user.id):
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"no {what} with id {obj_id}")
    return obj
