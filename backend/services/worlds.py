"""Worlds: accept an upload as a pending world (names, quota, the sandboxed read), list and
read worlds, and their predicted and measured errors. What the API's /worlds routes and the
dashboard's worlds pages call."""

from __future__ import annotations

import hashlib
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.core.config import Settings
from backend.core.schemas import WorldOut
from backend.db.models import Run, World
from backend.sandbox.manager import shared_sandbox
from backend.services import quotas
from backend.services.access import Principal, owned
from backend.services.errors import Conflict, Invalid, TooLarge
from backend.services.world_analysis import remember
from backend.store import create_pending_world, world_occupancy
from worker.errors import InputError
from worker.world.floorplan import TEXT_MAX, Floorplan, floorplan_header, pack_floorplan
from worker.world.image_io import ImageTooLarge

if TYPE_CHECKING:  # the API process loads the model only when a prediction is asked for
    from worker.predict.service import PredictionCache

_SAFE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._ -]{0,120}$")


def list_worlds(session: Session, user: Principal) -> list[WorldOut]:
    """The worlds the user owns (all of them for an admin), newest first."""
    stmt = select(World).order_by(World.id.desc())
    if not user.is_admin:
        stmt = stmt.where(World.owner_id == user.id)
    return [WorldOut.of(w) for w in session.scalars(stmt)]


def world_of(session: Session, user: Principal, world_id: int) -> World:
    """The world, or NotFound (also for another owner's)."""
    return owned(user, session.get(World, world_id), "world", world_id)


def ready_world(session: Session, user: Principal, world_id: int) -> World:
    """The world, NotFound, or Conflict when it is not ready (pending or invalid)."""
    w = world_of(session, user, world_id)
    if w.status != "ready":
        raise Conflict(not_ready(w))
    return w


def checked_names(filenames: Sequence[str | None]) -> list[str]:
    """The uploaded files' names (their base names); Invalid on an unsafe or repeated one."""
    names: list[str] = []
    for filename in filenames:
        name = Path(filename or "").name
        if not _SAFE_NAME.match(name):
            raise Invalid(f"unsafe file name {filename!r}")
        if name in names:
            raise Invalid(f"file {name!r} uploaded twice")
        names.append(name)
    return names


def _main_file(names: list[str]) -> tuple[str, str]:
    """(the floorplan file among the uploads, its format): a YAML, else a .world, else the image."""
    by_suffix = {n: Path(n).suffix.lower() for n in names}
    for fmt, suffixes in (("yaml", {".yaml", ".yml"}), ("stage", {".world"})):
        found = [n for n, s in by_suffix.items() if s in suffixes]
        if len(found) > 1:
            raise Invalid(f"more than one {fmt} file uploaded")
        if found:
            return found[0], fmt
    if len(names) == 1:
        return names[0], "image"  # the check says so if it is not an image
    raise Invalid(
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
    Stage world are InputError, too many pixels TooLarge."""
    try:
        parsed = shared_sandbox(settings).run(
            "floorplan", files, file=main, resolution=resolution,
            max_pixels=settings.max_image_pixels,
        )  # fmt: skip
    except ImageTooLarge as exc:
        raise TooLarge(str(exc)) from None
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
    quotas.check_upload(session, user.id, settings)  # QuotaExceeded before anything is stored
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


def not_ready(w: World) -> str:
    """Why a world cannot be used yet (pending) or at all (invalid)."""
    if w.status == "pending":
        return f"world {w.id} is still being analysed (pending); try again shortly"
    return f"world {w.id} is invalid: {w.error}"


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


def world_prediction_of(
    cache: PredictionCache, session: Session, w: World, slam: str
) -> dict[str, Any]:
    """Predicted errors of a ready world (`cache`: per content) and its measured ones."""
    out = cache.get((w.id, w.sha256), lambda: stored_floorplan(w), slam)
    return {**out, "world_id": w.id, "measured": measured_errors(session, w.id, slam)}


def occupancy(world: World) -> np.ndarray:
    """A stored world's occupancy grid `(H, W) bool`, `[iy, ix]` bottom row first."""
    return world_occupancy(world)
