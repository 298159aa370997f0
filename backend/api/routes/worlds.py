"""Worlds: upload a floorplan (image + resolution, map_server YAML + image, Stage .world +
bitmap), list them, read one, and get its image."""

from __future__ import annotations

import hashlib
import io
import re
import tempfile
from pathlib import Path
from typing import Annotated

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Query, Request, UploadFile, status
from fastapi.responses import JSONResponse, Response
from sqlalchemy import select

from backend import quotas
from backend.api.deps import CurrentUser, SessionDep, SettingsDep, owned
from backend.db.models import World
from backend.schemas import WorldOut
from backend.store import save_world, world_occupancy
from worker.errors import InputError

router = APIRouter(tags=["worlds"])

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._ -]{0,120}$")


def _read_uploads(files: list[UploadFile], limit: int) -> dict[str, bytes]:
    """Name -> bytes of the uploaded files; 413 past `limit` bytes in all, 400 on bad names."""
    out: dict[str, bytes] = {}
    total = 0
    for f in files:
        name = Path(f.filename or "").name
        if not _SAFE_NAME.match(name):
            raise HTTPException(status.HTTP_400_BAD_REQUEST, f"unsafe file name {f.filename!r}")
        if name in out:
            raise HTTPException(status.HTTP_400_BAD_REQUEST, f"file {name!r} uploaded twice")
        data = f.file.read(limit + 1 - total)
        total += len(data)
        if total > limit:
            raise HTTPException(
                status.HTTP_413_CONTENT_TOO_LARGE, f"upload larger than {limit:,} bytes"
            )
        out[name] = data
    return out


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
        return names[0], "image"  # the loader says so if it is not an image
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


@router.post("/worlds", response_model=WorldOut, status_code=status.HTTP_201_CREATED)
def upload_world(
    request: Request,
    session: SessionDep,
    user: CurrentUser,
    settings: SettingsDep,
    file: Annotated[list[UploadFile], File(description="The floorplan file(s).")],
    resolution: Annotated[float | None, Form(gt=0, description="metres per pixel")] = None,
) -> JSONResponse:
    """Store a floorplan; the same content uploaded again answers 200 with the existing world."""
    from worker.world.loader import load_world

    quotas.check_upload(session, user.id, settings)  # 429 before anything is stored

    declared = request.headers.get("content-length")
    if declared and declared.isdigit() and int(declared) > settings.max_upload_bytes + 65536:
        raise HTTPException(
            status.HTTP_413_CONTENT_TOO_LARGE,
            f"upload larger than {settings.max_upload_bytes:,} bytes",
        )
    files = _read_uploads(file, settings.max_upload_bytes)
    main, fmt = _main_file(list(files))
    sha = _content_hash(files, resolution)
    existing = session.scalars(
        select(World).where(World.owner_id == user.id, World.sha256 == sha)
    ).first()
    if existing is not None:
        return JSONResponse(WorldOut.of(existing).model_dump(mode="json"), status_code=200)
    with tempfile.TemporaryDirectory(prefix="mapqual-upload-") as tmp:
        for name, data in files.items():
            (Path(tmp) / name).write_bytes(data)
        try:
            world = load_world(Path(tmp) / main, resolution)
        except InputError as exc:  # -> 400, naming the uploaded file rather than our temp path
            raise InputError(str(exc).replace(f"{tmp}/", "")) from None
    row = save_world(session, owner_id=user.id, world=world, sha256=sha, source_format=fmt)
    row.source_path = main
    session.flush()
    return JSONResponse(WorldOut.of(row).model_dump(mode="json"), status_code=201)


@router.get("/worlds", response_model=list[WorldOut])
def list_worlds(session: SessionDep, user: CurrentUser) -> list[WorldOut]:
    """The worlds you own (all of them for an admin), newest first."""
    stmt = select(World).order_by(World.id.desc())
    if not user.is_admin:
        stmt = stmt.where(World.owner_id == user.id)
    return [WorldOut.of(w) for w in session.scalars(stmt)]


@router.get("/worlds/{world_id}", response_model=WorldOut)
def get_world(world_id: int, session: SessionDep, user: CurrentUser) -> WorldOut:
    """A world's facts and start pose."""
    return WorldOut.of(owned(user, session.get(World, world_id), "world", world_id))


def shrink_occupancy(occ: np.ndarray, max_px: int) -> np.ndarray:
    """occ (H, W) bool reduced by a whole factor until both sides are <= max_px; a block is an
    obstacle when any of its cells is (one-cell walls survive, as they would not a resize)."""
    f = -(-max(occ.shape) // max_px)
    if f <= 1:
        return occ
    h, w = -(-occ.shape[0] // f) * f, -(-occ.shape[1] // f) * f
    padded = np.zeros((h, w), dtype=bool)
    padded[: occ.shape[0], : occ.shape[1]] = occ
    return padded.reshape(h // f, f, w // f, f).any(axis=(1, 3))


@router.get("/worlds/{world_id}/image", response_class=Response)
def world_image(
    world_id: int,
    session: SessionDep,
    user: CurrentUser,
    max_px: Annotated[int | None, Query(ge=16, le=4096)] = None,
) -> Response:
    """The floorplan as the pipeline sees it: PNG, obstacles black, free white; with max_px,
    a thumbnail no side of which exceeds it (obstacles kept)."""
    from PIL import Image

    w = owned(user, session.get(World, world_id), "world", world_id)
    occ = world_occupancy(w)
    if max_px is not None:
        occ = shrink_occupancy(occ, max_px)
    img = Image.fromarray(np.where(np.flipud(occ), 0, 255).astype(np.uint8), mode="L")
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=True)
    return Response(buf.getvalue(), media_type="image/png")
