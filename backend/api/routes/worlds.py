"""Worlds: upload a floorplan (image + resolution, map_server YAML + image, Stage .world +
bitmap), list them, read one, and get its image."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Annotated, Any

from fastapi import APIRouter, File, Form, Query, Request, UploadFile
from fastapi.responses import JSONResponse, Response
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend.api.deps import (
    CurrentUser,
    IdPath,
    SessionDep,
    SettingsDep,
    in_session,
    prediction_cache,
    world_pool,
)
from backend.core.config import Settings
from backend.core.schemas import WorldOut
from backend.db.models import World
from backend.services import worlds
from backend.store import world_occupancy
from worker.world.picture import occupancy_png

router = APIRouter(tags=["worlds"])

POLL_S = 0.25  # [s] between looks at a world another process is analysing (`wait`)


def _world_out(session: Session, world_id: int) -> WorldOut:
    return WorldOut.of(session.get_one(World, world_id))


async def settle(request: Request, settings: Settings, out: WorldOut, wait: float) -> WorldOut:
    """`out` after waiting up to `wait` seconds for its analysis, on the event loop (no thread
    is held meanwhile); a world analysed by another process is polled instead."""
    if out.status != "pending" or wait <= 0:
        return out
    deadline = asyncio.get_running_loop().time() + wait
    future = world_pool(request.app).running(out.id)
    if future is not None:
        # still pending at the deadline, or the pool failed (the world is then invalid)
        with contextlib.suppress(Exception):
            await asyncio.wait_for(asyncio.shield(asyncio.wrap_future(future)), wait)
    while True:
        out = await run_in_threadpool(in_session, settings, _world_out, out.id)
        left = deadline - asyncio.get_running_loop().time()
        if out.status != "pending" or left <= 0:
            return out
        await asyncio.sleep(min(POLL_S, left))


_ANSWERS: dict[str, Any] = {
    200: {"model": WorldOut, "description": "The same content was uploaded before: that world."},
    201: {"model": WorldOut, "description": "Analysed within `wait`: ready."},
    202: {"model": WorldOut, "description": "Stored, analysis pending (poll GET /worlds/{id})."},
    400: {"description": "Bad files, or analysed within `wait` and invalid (the reason)."},
    413: {"description": "Body over the upload limit, or an image over the pixel limit."},
}


@router.post("/worlds", response_model=WorldOut, status_code=202, responses=_ANSWERS)
async def upload_world(
    request: Request,
    user: CurrentUser,
    settings: SettingsDep,
    file: Annotated[list[UploadFile], File(description="The floorplan file(s).")],
    resolution: Annotated[float | None, Form(gt=0, description="metres per pixel")] = None,
    wait: Annotated[
        float, Query(ge=0, le=30, description="Seconds to wait for the analysis's outcome.")
    ] = 0.0,
) -> JSONResponse:
    """Store a floorplan (202, pending) and analyse it off the request thread; with `wait`,
    answer its outcome if it comes in time: 201 ready, 400 invalid (with the reason)."""
    names = worlds.checked_names([f.filename for f in file])
    # The body limit (BodyLimit) bounds these reads; the files are spooled, not in memory.
    files = {name: await f.read() for name, f in zip(names, file, strict=True)}
    row, fresh = await run_in_threadpool(
        in_session, settings, worlds.accept_upload, user, settings, files, resolution
    )
    out = WorldOut.of(row)
    if fresh:
        world_pool(request.app).submit(out.id)
    out = await settle(request, settings, out, wait)
    return world_answer(out, fresh)


def world_answer(out: WorldOut, fresh: bool) -> JSONResponse:
    """201/200 ready (new/existing), 202 pending, 400 invalid with its reason."""
    if out.status == "invalid":
        return JSONResponse({"detail": out.error, "world": out.model_dump(mode="json")}, 400)
    code = 202 if out.status == "pending" else (201 if fresh else 200)
    return JSONResponse(out.model_dump(mode="json"), status_code=code)


@router.get("/worlds", response_model=list[WorldOut])
def list_worlds(session: SessionDep, user: CurrentUser) -> list[WorldOut]:
    """The worlds you own (all of them for an admin), newest first."""
    return worlds.list_worlds(session, user)


@router.get("/worlds/{world_id}", response_model=WorldOut)
def get_world(world_id: IdPath, session: SessionDep, user: CurrentUser) -> WorldOut:
    """A world's facts and start pose."""
    return WorldOut.of(worlds.world_of(session, user, world_id))


@router.get("/worlds/{world_id}/image", response_class=Response)
def world_image(
    world_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    max_px: Annotated[int | None, Query(ge=16, le=4096)] = None,
) -> Response:
    """The floorplan as the pipeline sees it: PNG, obstacles black, free white; with max_px,
    a thumbnail no side of which exceeds it (obstacles kept)."""
    w = worlds.ready_world(session, user, world_id)
    return Response(occupancy_png(world_occupancy(w), max_px), media_type="image/png")


@router.get("/worlds/{world_id}/prediction")
def world_prediction(
    world_id: IdPath,
    request: Request,
    session: SessionDep,
    user: CurrentUser,
    slam: Annotated[str, Query(max_length=40, description="SLAM algorithm")] = "rbpf",
) -> dict[str, Any]:
    """Map quality predicted from the floorplan alone by the bundled model: mean B errors with
    an 80 % interval, success probability, the features that drove them; and the measured
    errors of the world's runs, when there are any (400: no such model part, or no enclosed
    free space)."""
    w = worlds.ready_world(session, user, world_id)
    return worlds.world_prediction_of(prediction_cache(request.app), session, w, slam)
