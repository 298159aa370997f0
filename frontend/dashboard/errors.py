"""Error answers as the client wants them: a browser asking for a page (Accept: text/html)
gets an HTML page with the navigation and a way back; the API and every other client get
FastAPI's JSON `{"detail": ...}`, unchanged."""

from __future__ import annotations

from fastapi import Request
from fastapi.exception_handlers import (
    http_exception_handler,
    request_validation_exception_handler,
)
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.responses import Response

API_PREFIX = "/api/"
TITLES = {400: "Bad request", 401: "Not signed in", 403: "Not allowed", 404: "Not found",
          405: "Method not allowed", 413: "Too large", 422: "Invalid request",
          429: "Too many requests"}  # fmt: skip


def wants_html(request: Request) -> bool:
    """A browser's page request: not the API, and text/html among what it accepts."""
    if request.url.path.startswith(API_PREFIX) or request.url.path.startswith("/static/"):
        return False
    return "text/html" in request.headers.get("accept", "")


def _page(request: Request, status: int, detail: str) -> Response:
    from frontend.dashboard.pages import render

    title = TITLES.get(status, "Error")
    return render(request, "error.html", status, code=status, title=title, detail=detail,
                  error_page=True)  # fmt: skip


async def http_error(request: Request, exc: StarletteHTTPException) -> Response:
    if not wants_html(request) or exc.status_code < 400:
        return await http_exception_handler(request, exc)
    detail = exc.detail if isinstance(exc.detail, str) else "the request cannot be served"
    return _page(request, exc.status_code, detail)


async def validation_error(request: Request, exc: RequestValidationError) -> Response:
    if not wants_html(request):
        return await request_validation_exception_handler(request, exc)
    parts = [f"{'.'.join(str(p) for p in e.get('loc', ())[1:])}: {e.get('msg', '')}"
             for e in exc.errors()[:5]]  # fmt: skip
    return _page(request, 400, "invalid request: " + "; ".join(parts))
