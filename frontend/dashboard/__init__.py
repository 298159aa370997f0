"""The dashboard: server-rendered pages over the API's own handlers and access rules, with
their templates, static files and charts; `mapqual.app` mounts it at /."""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.exceptions import RequestValidationError
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from frontend.dashboard import compare, errors, explore, pages, worlds

STATIC = Path(__file__).resolve().parent / "static"


def install(app: FastAPI) -> None:
    """Add the pages, their static files and the sign-in redirect to `app`."""
    for module in (pages, worlds, compare, explore):
        app.include_router(module.router)
    app.mount("/static", StaticFiles(directory=STATIC), name="static")
    app.add_exception_handler(pages.SignInRequired, pages.sign_in_redirect)
    # browsers get error pages with the navigation; the API keeps its JSON
    app.add_exception_handler(StarletteHTTPException, errors.http_error)
    app.add_exception_handler(RequestValidationError, errors.validation_error)
