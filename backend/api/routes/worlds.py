"""Worlds: upload a floorplan (image + resolution, map_server YAML + image, Stage .world +
bitmap), list them, read one, and get its image."""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import re
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Query, Request, UploadFile, status
from fastapi.responses import JSONResponse, Response
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session
from starlette.concurrency import run_in_threadpool

from backend import quotas
from backend.api.deps import (
    CurrentUser,
    IdPath,
    Principal,
    SessionDep,
    SettingsDep,
    in_session,
    owned,
)
from backend.core.config import Settings
from backend.db.models import World
from backend.sandbox import shared_sandbox
from backend.schemas import WorldOut
from backend.store import create_pending_world, world_occupancy
from backend.world_analysis import PLAN, remember, world_pool
from worker.errors import InputError
from worker.world.floorplan import TEXT_MAX, Floorplan, floorplan_header, pack_floorplan
from worker.world.image_io import ImageTooLarge
from worker.world.picture import occupancy_png

router = APIRouter(tags=["worlds"])

POLL_S = 0.25  # [s] between looks at a world another process is analysing (`wait`)
_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._ -]{0,120}$")


def checked_names(files: list[UploadFile]) -> list[str]:
    """The uploaded files' names; 400 on an unsafe or repeated one."""
    names: list[str] = []
    for f in files:
        name = Path(f.filename or "").name
        if not _SAFE_NAME.match(name):
            raise HTTPException(status.HTTP_400_BAD_REQUEST, f"unsafe file name {f.filename!r}")
        if name in names:
            raise HTTPException(status.HTTP_400_BAD_REQUEST, f"file {name!r} uploaded twice")
        names.append(name)
    return names


def _main_file(names: list[str]) -> tuple[str, str]:
    """(the floorplan file among the uploads, its format): a YAML, else a .world, else the image."""
    by_suffix = {n: Path(n).suffix.lower() for n in names}
    for fmt, suffixes in (("yaml", {".yaml", ".yml"}), ("stage", {".world"})):
        found = [n for n, s in by_suffix.items() if s in suffixes]
        if len(found) > 1:
            raise HTTPException(status.HTTP_400_BAD_REQUEST, f"more than one {fmt} file uploaded")
        if found:
            return found[0], fmt
    if len(names) == 1:
        return names[0], "image"  # the check says so if it is not an image
    raise HTTPException(
        status.HTTP_400_BAD_REQUEST,
        "upload one image, or a map_server YAML with its image, or a Stage .world with its bitmap",
    )


def _content_hash(files: dict[str, bytes], resolution: float | None) -> str:
    h = hashlib.sha256()
    for name in sorted(files):
        h.update(name.encode() + b"\0" + hashlib.sha256(files[name]).digest())
    h.update(repr(resolution).encode())
    return h.hexdigest()


def read_upload(
    settings: Settings, files: dict[str, bytes], main: str, resolution: float | None
) -> bytes:
    """The upload read into a floorplan's bytes (`worker.world.floorplan`), in the upload
    sandbox (a limited process), the only place its raw bytes are parsed: references leaving
    the uploaded files, a missing or bad resolution, an unreadable image, a malformed YAML or
    Stage world are 400, too many pixels 413."""
    try:
        parsed = shared_sandbox(settings).run(
            "floorplan", files, file=main, resolution=resolution,
            max_pixels=settings.max_image_pixels,
        )  # fmt: skip
    except ImageTooLarge as exc:
        raise HTTPException(status.HTTP_413_CONTENT_TOO_LARGE, str(exc)) from None
    if parsed.blob is None:
        raise InputError(f"{main}: could not be read (no result)")
    floorplan_header(parsed.blob, settings.max_image_pixels)  # InputError if malformed
    remember(parsed.blob, parsed.facts.get("analysis"))  # a small plan's, made there too
    return parsed.blob


def accept_upload(
    session: Session,
    user: Principal,
    settings: Settings,
    files: dict[str, bytes],
    resolution: float | None,
) -> tuple[World, bool]:
    """Check an upload and store it as a pending world: (the world, whether it needs an
    analysis). The same content again is the existing world (an invalid one is retried)."""
    main, fmt = _main_file(list(files))
    sha = _content_hash(files, resolution)
    existing = session.scalars(
        select(World).where(World.owner_id == user.id, World.sha256 == sha)
    ).first()
    if existing is not None and existing.status != "invalid":
        return existing, False
    quotas.check_upload(session, user.id, settings)  # 429 before anything is stored
    plan = read_upload(settings, files, main, resolution)
    if existing is not None:
        session.delete(existing)  # invalid worlds have no jobs; the retry gets a new id
        session.flush()
    try:
        with session.begin_nested():  # the same upload racing in: the first one stays
            row = create_pending_world(
                session, owner_id=user.id, name=Path(main).stem, sha256=sha, source_format=fmt,
                source_path=main, upload=plan, resolution=resolution,
            )  # fmt: skip
    except IntegrityError:
        return session.scalars(
            select(World).where(World.owner_id == user.id, World.sha256 == sha)
        ).one(), False
    return row, True


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
    names = checked_names(file)
    # The body limit (BodyLimit) bounds these reads; the files are spooled, not in memory.
    files = {name: await f.read() for name, f in zip(names, file, strict=True)}
    row, fresh = await run_in_threadpool(
        in_session, settings, accept_upload, user, settings, files, resolution
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
    stmt = select(World).order_by(World.id.desc())
    if not user.is_admin:
        stmt = stmt.where(World.owner_id == user.id)
    return [WorldOut.of(w) for w in session.scalars(stmt)]


@router.get("/worlds/{world_id}", response_model=WorldOut)
def get_world(world_id: IdPath, session: SessionDep, user: CurrentUser) -> WorldOut:
    """A world's facts and start pose."""
    return WorldOut.of(owned(user, session.get(World, world_id), "world", world_id))


def not_ready(w: World) -> str:
    """Why a world cannot be used yet (pending) or at all (invalid)."""
    if w.status == "pending":
        return f"world {w.id} is still being analysed (pending); try again shortly"
    return f"world {w.id} is invalid: {w.error}"


@router.get("/worlds/{world_id}/image", response_class=Response)
def world_image(
    world_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    max_px: Annotated[int | None, Query(ge=16, le=4096)] = None,
) -> Response:
    """The floorplan as the pipeline sees it: PNG, obstacles black, free white; with max_px,
    a thumbnail no side of which exceeds it (obstacles kept)."""
    w = owned(user, session.get(World, world_id), "world", world_id)
    if w.status != "ready":
        raise HTTPException(status.HTTP_409_CONFLICT, not_ready(w))
    return Response(occupancy_png(world_occupancy(w), max_px), media_type="image/png")


def prediction_cache(app) -> Any:
    """The app's cache of world predictions (made on first use), each computed in the
    analysis sandbox (a limited process: address space, CPU and wall time)."""
    from worker.predict.service import PredictionCache

    cache = getattr(app.state, "prediction_cache", None)
    if cache is None:
        settings = app.state.settings
        box = shared_sandbox(settings, "analysis")

        def compute(plan_of, slam: str, _model: dict) -> dict:
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


def stored_floorplan(w: World) -> bytes:
    """A ready world's grid and geometry as a floorplan's bytes (what an analysis reads)."""
    plan = Floorplan(
        name=w.name[:TEXT_MAX], occ=world_occupancy(w), resolution=w.resolution,
        origin=(w.origin_x, w.origin_y), start_pose=tuple(w.start_pose),
        n_rooms=w.facts.get("n_rooms"), notes=(), source=w.name[:TEXT_MAX],
    )  # fmt: skip
    return pack_floorplan(plan)


def measured_errors(session: Session, world_id: int, slam: str) -> dict[str, Any]:
    """The world's measured mean B errors: means over its runs of `slam` that have them."""
    from backend.db.models import Run

    rows = session.execute(
        select(Run.b_mean_t, Run.b_mean_r).where(
            Run.world_id == world_id, Run.slam == slam, Run.b_mean_t.is_not(None)
        )
    ).all()
    if not rows:
        return {"runs": 0, "b_mean_t": None, "b_mean_r": None}
    return {
        "runs": len(rows),
        "b_mean_t": float(np.mean([r[0] for r in rows])),
        "b_mean_r": float(np.mean([r[1] for r in rows if r[1] is not None] or [np.nan])),
    }


def world_prediction_of(app, session: Session, w: World, slam: str) -> dict[str, Any]:
    """Predicted errors of a ready world (cached per content) and its measured ones."""
    out = prediction_cache(app).get((w.id, w.sha256), lambda: stored_floorplan(w), slam)
    return {**out, "world_id": w.id, "measured": measured_errors(session, w.id, slam)}


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
    w = owned(user, session.get(World, world_id), "world", world_id)
    if w.status != "ready":
        raise HTTPException(status.HTTP_409_CONFLICT, not_ready(w))
    return world_prediction_of(request.app, session, w, slam)
