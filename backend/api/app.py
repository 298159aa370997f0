"""The REST API as a FastAPI application; `mapqual.app` adds the dashboard above it (backend
imports no frontend)."""

from __future__ import annotations

import gc
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from sqlalchemy.exc import SQLAlchemyError
from starlette.concurrency import run_in_threadpool

from backend.api import errors
from backend.api.deps import recover_pending, world_pool
from backend.api.limits import BodyLimit
from backend.api.manual import MOUNT as MANUAL_MOUNT
from backend.api.manual import Manual
from backend.api.routes import bags, datasets, health, jobs, runs, stats, worlds
from backend.core.config import Settings, get_settings
from backend.core.schemas import API_PREFIX
from backend.sandbox.manager import sandbox, scrub_paths, server_folders
from worker.errors import InputError

log = logging.getLogger("mapqual.api")


_frozen = False


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    """At the first start in a process, move everything alive then (modules, routes, ORM
    mappers, schemas: it lives as long as the process) out of the cyclic garbage collector's
    sight. A full collection then scans only what requests made since, instead of ~200,000
    objects: a 50-130 ms pause that every request in flight would wait out (p99 latency).

    Worlds a dead process left `pending` are analysed again; at the end the world pool's
    processes stop (what they had not started stays pending for the next start)."""
    global _frozen
    if not _frozen:
        _frozen = True
        gc.collect()
        gc.freeze()
    try:
        recovered = await run_in_threadpool(recover_pending, app)
        if recovered:
            log.info("analysing %d world(s) left pending: %s", len(recovered), recovered)
    except SQLAlchemyError as exc:  # no database yet: the API still starts (health says so)
        log.warning("could not look for pending worlds: %s", exc.__class__.__name__)
    sandbox(app).start()  # the upload parsers load while the API starts serving
    world_pool(app).start()  # and the world analysis's
    try:
        yield
    finally:
        await run_in_threadpool(world_pool(app).shutdown)
        await run_in_threadpool(sandbox(app).shutdown)


def create_api(settings: Settings | None = None) -> FastAPI:
    """A configured API; tests pass their own settings (database, broker, auth)."""
    settings = settings or get_settings()
    app = FastAPI(
        title="mapqual",
        version="0.1.0",
        description="Automatic map-quality evaluation of SLAM algorithms: upload a floorplan, "
        "submit runs, fetch metrics, trajectories and maps.",
        openapi_url=f"{API_PREFIX}/openapi.json",
        docs_url=f"{API_PREFIX}/docs",
        lifespan=_lifespan,
    )
    app.state.settings = settings
    if settings.auth == "off":
        log.warning("authentication is OFF (MAPQUAL_AUTH=off): every request acts as 'local'")

    @app.exception_handler(InputError)
    async def _input_error(_request: Request, exc: InputError) -> JSONResponse:
        # no server path in an answer: the temporary, sandbox and runs folders shortened
        return JSONResponse({"detail": scrub_paths(str(exc), *server_folders(settings))}, 400)

    errors.install(app)  # the services' typed errors as HTTP answers
    app.include_router(health.router)
    # jobs first: routes are matched in order, and GET /jobs/{id} and POST /jobs are the hot
    # paths (each route tried before them costs every such request a match)
    for module in (jobs, worlds, datasets, runs, bags, stats):
        app.include_router(module.router, prefix=API_PREFIX)
    # the manual at /manual/, before the dashboard's catch-all pages (`mapqual.app`)
    app.mount(MANUAL_MOUNT, Manual(), name="manual")
    # outermost: bodies are counted before any parser (or other middleware) reads them
    app.add_middleware(BodyLimit, max_bytes=settings.max_upload_bytes)
    return app
