"""The one place where the services' typed errors become HTTP answers: a status per error
class, the body FastAPI gives an HTTPException (`{"detail": ...}`), and the app's own handler
for it (so the dashboard's error pages still serve browsers)."""

from __future__ import annotations

from fastapi import FastAPI, Request, status
from fastapi.exception_handlers import http_exception_handler
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response

from backend.services.errors import (
    Conflict,
    Invalid,
    NotFound,
    QuotaExceeded,
    ServiceError,
    TooLarge,
    Unavailable,
)

STATUS: dict[type[ServiceError], int] = {
    Invalid: status.HTTP_400_BAD_REQUEST,
    TooLarge: status.HTTP_413_CONTENT_TOO_LARGE,
    NotFound: status.HTTP_404_NOT_FOUND,
    Conflict: status.HTTP_409_CONFLICT,
    QuotaExceeded: status.HTTP_429_TOO_MANY_REQUESTS,
    Unavailable: status.HTTP_503_SERVICE_UNAVAILABLE,
}


def as_http(exc: ServiceError) -> StarletteHTTPException:
    """The HTTP error that `exc` is (400 for a ServiceError of no listed kind)."""
    code = next((c for kind, c in STATUS.items() if isinstance(exc, kind)), 400)
    return StarletteHTTPException(code, exc.detail, headers=exc.headers)


async def service_error(request: Request, exc: Exception) -> Response:
    """Answer a ServiceError as the app answers the HTTPException it maps to."""
    assert isinstance(exc, ServiceError)
    http = as_http(exc)
    handler = request.app.exception_handlers.get(StarletteHTTPException, http_exception_handler)
    return await handler(request, http)


def install(app: FastAPI) -> None:
    """Map every ServiceError raised under `app` to its HTTP answer."""
    app.add_exception_handler(ServiceError, service_error)
