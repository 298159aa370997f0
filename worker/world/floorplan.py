"""A floorplan's files read into what `World.from_array` needs, and its byte form.

An upload is read once, in the API's upload sandbox (`backend.sandbox.manager`): there its images
are decoded and its YAML or Stage file parsed into a `Floorplan`; the API stores that
floorplan's bytes (`pack_floorplan`), never the raw upload, and the world's analysis (the
grid's regions, clearance, start pose) starts from them. `unpack_floorplan` checks every
field, so bytes of any origin give a valid Floorplan or an InputError, never more.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np

from worker.errors import InputError

MAGIC = b"mapqual-floorplan-1\n"
HEADER_MAX = 64 * 1024  # [bytes] of the JSON header (names and notes)
NOTES_MAX = 32
TEXT_MAX = 500  # [characters] of a name, the source or one note


@dataclass(frozen=True, eq=False)
class Floorplan:
    """A floorplan read from its files: the grid and what its description said."""

    name: str
    occ: np.ndarray  # (H, W) bool, True = obstacle, row 0 the BOTTOM row
    resolution: float  # [m/cell]
    origin: tuple[float, float]  # [m] world position of the grid's lower-left corner
    start_pose: tuple[float, float, float] | None  # [x, y, theta] (a Stage robot), or None
    n_rooms: int | None  # rooms of a segmentation image, when one was given
    notes: tuple[str, ...]  # how the files were read (the world's warnings)
    source: str  # the file it was read from


def pack_floorplan(plan: Floorplan) -> bytes:
    """`plan` as bytes: MAGIC, one JSON line (the fields but the grid), the grid's bits."""
    h, w = plan.occ.shape
    header = {
        "name": plan.name, "shape": [int(h), int(w)], "resolution": float(plan.resolution),
        "origin": [float(v) for v in plan.origin],
        "start_pose": None if plan.start_pose is None else [float(v) for v in plan.start_pose],
        "n_rooms": plan.n_rooms, "notes": list(plan.notes), "source": plan.source,
    }  # fmt: skip
    bits = np.packbits(np.asarray(plan.occ, dtype=bool), axis=None)
    return MAGIC + json.dumps(header).encode() + b"\n" + bits.tobytes()


def floorplan_header(blob: bytes, max_pixels: int) -> dict:
    """The checked header of `pack_floorplan`'s bytes (the grid's length checked too, its
    bits not unpacked); InputError on anything else."""
    if not blob.startswith(MAGIC):
        raise _malformed()
    end = blob.find(b"\n", len(MAGIC), len(MAGIC) + HEADER_MAX)
    if end < 0:
        raise _malformed()
    try:
        head = json.loads(blob[len(MAGIC) : end])
    except ValueError:
        raise _malformed() from None
    if not isinstance(head, dict) or not _valid(head, max_pixels):
        raise _malformed()
    h, w = head["shape"]
    if len(blob) - end - 1 != (h * w + 7) // 8:
        raise _malformed()
    return head


def unpack_floorplan(blob: bytes, max_pixels: int) -> Floorplan:
    """The Floorplan of `pack_floorplan`'s bytes, every field checked."""
    head = floorplan_header(blob, max_pixels)
    h, w = head["shape"]
    start = len(blob) - (h * w + 7) // 8
    bits = np.frombuffer(blob, np.uint8, offset=start)
    occ = np.unpackbits(bits, count=h * w).astype(bool).reshape(h, w)
    pose = head["start_pose"]
    return Floorplan(
        name=head["name"], occ=occ, resolution=head["resolution"],
        origin=(head["origin"][0], head["origin"][1]),
        start_pose=None if pose is None else (pose[0], pose[1], pose[2]),
        n_rooms=head["n_rooms"], notes=tuple(head["notes"]), source=head["source"],
    )  # fmt: skip


def _valid(head: dict, max_pixels: int) -> bool:
    shape, pose, rooms = head.get("shape"), head.get("start_pose"), head.get("n_rooms")
    return (
        _ints(shape, 2) and 0 < shape[0] * shape[1] <= max_pixels and min(shape) > 0
        and _numbers(head.get("origin"), 2) and _numbers([head.get("resolution")], 1)
        and 0 < head["resolution"] <= 1.0
        and (pose is None or _numbers(pose, 3))
        and (rooms is None or (_ints([rooms], 1) and rooms >= 0))
        and _text(head.get("name")) and _text(head.get("source"))
        and isinstance(head.get("notes"), list) and len(head["notes"]) <= NOTES_MAX
        and all(_text(n) for n in head["notes"])
    )  # fmt: skip


def _ints(values: object, n: int) -> bool:
    return (
        isinstance(values, list) and len(values) == n
        and all(type(v) is int for v in values)
    )  # fmt: skip


def _numbers(values: object, n: int) -> bool:
    return (
        isinstance(values, list) and len(values) == n
        and all(type(v) in (int, float) and math.isfinite(v) for v in values)
    )  # fmt: skip


def _text(value: object) -> bool:
    return isinstance(value, str) and len(value) <= TEXT_MAX


def _malformed() -> InputError:
    return InputError("the floorplan could not be read (a malformed result)")
