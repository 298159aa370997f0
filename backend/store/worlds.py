"""Persistence of worlds: stored at once from a loaded floorplan, or pending (uploaded, analysed
off the request thread) until their analysis makes them ready or invalid."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np
from sqlalchemy import select, update
from sqlalchemy.orm import Session

from backend.db.arrays import pack_array, unpack_array
from backend.db.models import World
from worker.status import WorldStatus
from worker.world.world import World as WorldModel


def get_or_create_world(
    session: Session,
    *,
    owner_id: int,
    name: str,
    sha256: str,
    source_format: str,
    source_path: str | None,
    resolution: float,
    origin: Sequence[float],
    occ: np.ndarray,
    start_pose: Sequence[float],
    facts: dict[str, Any],
) -> World:
    """The owner's world with this content hash, or a new one: uploading twice is harmless."""
    existing = session.scalars(
        select(World).where(World.owner_id == owner_id, World.sha256 == sha256)
    ).first()
    if existing is not None:
        return existing
    world = World(
        owner_id=owner_id,
        name=name,
        sha256=sha256,
        source_format=source_format,
        source_path=source_path,
        facts=facts,
        **_geometry(resolution, origin, occ, start_pose),
    )
    session.add(world)
    session.flush()
    return world


def _geometry(
    resolution: float, origin: Sequence[float], occ: np.ndarray, start_pose: Sequence[float]
) -> dict[str, Any]:
    """The geometry columns of an analysed world (`occ (H, W) bool`, bottom row first)."""
    return {
        "resolution": float(resolution),
        "origin_x": float(origin[0]),
        "origin_y": float(origin[1]),
        "width_px": int(occ.shape[1]),
        "height_px": int(occ.shape[0]),
        "start_pose": [float(v) for v in start_pose],
        "occupancy": pack_array(np.asarray(occ, dtype=bool)),
    }


def _facts(world: WorldModel) -> dict[str, Any]:
    """A loaded world's facts as stored, with the loader's warnings."""
    facts = dataclasses.asdict(world.facts)
    facts["warnings"] = list(world.warnings)
    return facts


def save_world(
    session: Session,
    *,
    owner_id: int,
    world: WorldModel,
    sha256: str,
    source_format: str,
) -> World:
    """Store a loaded floorplan (once per owner and content hash)."""
    return get_or_create_world(
        session,
        owner_id=owner_id,
        name=world.name,
        sha256=sha256,
        source_format=source_format,
        source_path=world.source,
        resolution=world.resolution,
        origin=world.origin,
        occ=world.occ,
        start_pose=world.start_pose,
        facts=_facts(world),
    )


def world_fingerprint(world: WorldModel) -> str:
    """A content hash of a loaded world (see `World.fingerprint`)."""
    return world.fingerprint()


def world_model(row: World) -> WorldModel:
    """The pipeline's World for a stored world (grid, resolution, origin, start pose)."""
    return WorldModel.from_array(
        world_occupancy(row),
        row.resolution,
        origin=(row.origin_x, row.origin_y),
        start_pose=tuple(row.start_pose),
        name=row.name,
        n_rooms=row.facts.get("n_rooms"),
        source=row.source_path,
    )


def world_occupancy(world: World) -> np.ndarray:
    """The stored occupancy grid `(H, W) bool`, `[iy, ix]` bottom row first."""
    return unpack_array(world.occupancy)


# --- worlds analysed off the request thread (pending -> ready | invalid) --------------------
def create_pending_world(
    session: Session,
    *,
    owner_id: int,
    name: str,
    sha256: str,
    source_format: str,
    source_path: str,
    upload: bytes,
    resolution: float | None,
) -> World:
    """A world whose files are stored (`upload`, packed) but not yet analysed: `pending`."""
    world = World(
        owner_id=owner_id,
        name=name,
        sha256=sha256,
        source_format=source_format,
        source_path=source_path,
        status=WorldStatus.PENDING,
        upload=upload,
        upload_resolution=resolution,
        facts={},
    )
    session.add(world)
    session.flush()
    return world


def mark_world_ready(session: Session, world_id: int, world: WorldModel) -> bool:
    """Fill a pending world's geometry and facts from its analysis, drop its upload; False if
    it is no longer pending (another process finished it first: the first result stays)."""
    values = {
        "status": WorldStatus.READY,
        "error": None,
        "upload": None,
        "facts": _facts(world),
        **_geometry(world.resolution, world.origin, world.occ, world.start_pose),
    }
    return _finish_world(session, world_id, values)


def mark_world_invalid(session: Session, world_id: int, error: str) -> bool:
    """A pending world whose files the loader refused: `invalid`, with its one-line reason
    (the upload is dropped); False if it is no longer pending."""
    return _finish_world(
        session, world_id, {"status": WorldStatus.INVALID, "error": error, "upload": None}
    )


def _finish_world(session: Session, world_id: int, values: dict[str, Any]) -> bool:
    """Compare-and-set on `status = pending`: two analyses of one world store one result."""
    result = session.execute(
        update(World)
        .where(World.id == world_id, World.status == WorldStatus.PENDING)
        .values(**values)
        .execution_options(synchronize_session=False)
    )
    return result.rowcount == 1


def pending_world_ids(session: Session) -> list[int]:
    """Worlds still waiting for their analysis (e.g. left by a process that died), oldest first."""
    stmt = select(World.id).where(World.status == WorldStatus.PENDING).order_by(World.id)
    return list(session.scalars(stmt))


def world_upload(session: Session, world_id: int) -> tuple[bytes, float | None, str] | None:
    """(packed upload, resolution given with it, main file name) of a pending world, or None."""
    row = session.execute(
        select(World.upload, World.upload_resolution, World.source_path).where(
            World.id == world_id, World.status == WorldStatus.PENDING
        )
    ).first()
    if row is None or row[0] is None:
        return None
    return bytes(row[0]), row[1], str(row[2])
