"""The mapqual-slam protocol's framing and messages: 4-byte big-endian length + one msgpack map.

Versions 1 and 2 (2 adds a map form: a list of changed cells), specified in
docs/external-slam.md. This module only encodes and checks messages;
worker.slam.external.process moves the bytes and worker.slam.external.client drives a run.
"""

from __future__ import annotations

import math
import struct
from typing import Any

import msgpack
import numpy as np

from worker.slam.external.kernels import (
    BAD_INDEX,
    check_cells,
    copy_float32,
    copy_int8,
    scatter,
)

PROTOCOL = "mapqual-slam"
VERSIONS = (1, 2)  # what mapqual speaks; 2 adds the map's `cells` form
VERSION = VERSIONS[-1]  # the newest
HEADER = struct.Struct(">I")  # payload length [bytes]
MAX_FRAME = 64 * 1024 * 1024  # [bytes] a longer frame is a protocol error (a 4000 x 4000 map)
ENCODINGS = {"float32": np.dtype("<f4"), "int8": np.dtype("i1")}


class ProtocolError(ValueError):
    """An answer that breaks the protocol (the message says what; the client adds the step)."""


def frame(message: dict[str, Any]) -> bytes:
    """One frame: the length header and the msgpack payload of `message`."""
    payload = msgpack.packb(message, use_bin_type=True)
    return HEADER.pack(len(payload)) + payload


def unpack(payload: bytes) -> dict[str, Any]:
    """The message of one frame's payload: a msgpack map with a string `type`."""
    try:
        message = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except (ValueError, msgpack.UnpackException, TypeError) as exc:
        raise ProtocolError(f"not a msgpack message ({type(exc).__name__}: {exc})") from None
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise ProtocolError(f"a message must be a map with a string 'type', got {_brief(message)}")
    return message


def hello() -> dict[str, Any]:
    """mapqual's opening message."""
    return {"type": "hello", "protocol": PROTOCOL, "versions": list(VERSIONS)}


def check_hello(message: dict[str, Any]) -> tuple[str, int]:
    """(the program's name, the version it chose) from its hello; ProtocolError on another
    protocol or a version mapqual does not speak."""
    expect(message, "hello")
    if message.get("protocol") != PROTOCOL:
        raise ProtocolError(f"hello names protocol {message.get('protocol')!r}, not {PROTOCOL!r}")
    version = message.get("version")
    if isinstance(version, bool) or version not in VERSIONS:
        speaks = " and ".join(str(v) for v in VERSIONS)
        raise ProtocolError(f"the program speaks version {version!r}; mapqual speaks {speaks}")
    name = message.get("name", "")
    return (name if isinstance(name, str) else ""), int(version)


def step(
    seq: int,
    t: float,
    pose_odom: np.ndarray,
    ranges_m: np.ndarray,
    trail: np.ndarray | None = None,
    *,
    map_due: bool = False,
) -> bytes:
    """The frame of step `seq`: time [s], odometry (3,) [x, y, theta], ranges (B,) [m] float64;
    with a gate, `trail` (K * 4,) float64 [t, x, y, theta] of the K steps not sent before it;
    map_due (version 2): mapqual will read the map if this scan updates it."""
    ranges = np.ascontiguousarray(ranges_m, dtype="<f8")
    odom = [float(pose_odom[0]), float(pose_odom[1]), float(pose_odom[2])]
    message = {"type": "step", "seq": seq, "t": float(t), "odom": odom, "ranges": ranges.data}
    if trail is not None:
        message["trail"] = np.ascontiguousarray(trail, dtype="<f8").data
    if map_due:
        message["map_due"] = True
    return frame(message)


def gate(value: Any) -> tuple[float, float, float]:
    """(linear_update [m], angular_update [rad], temporal_update [s]) of a ready's `gate`:
    two numbers >= 0 and one number (negative: no time rule)."""
    if not isinstance(value, dict):
        raise ProtocolError(f"ready 'gate' must be a map, got {_brief(value)}")
    linear, angular = number(value, "linear_update"), number(value, "angular_update")
    temporal = number(value, "temporal_update") if "temporal_update" in value else -1.0
    if linear < 0 or angular < 0:
        raise ProtocolError(
            f"ready 'gate': linear_update and angular_update must be >= 0, got {linear}, {angular}"
        )
    return linear, angular, temporal


def expect(message: dict[str, Any], kind: str) -> None:
    """ProtocolError unless `message` is of type `kind` (an `error` message says its own)."""
    if message["type"] == "error":
        raise ProtocolError(f"the program reported an error: {message.get('message', '')!s:.500}")
    if message["type"] != kind:
        raise ProtocolError(f"expected a {kind!r} message, got {message['type']!r}")


def pose3(message: dict[str, Any], key: str) -> np.ndarray:
    """(3,) [x, y, theta] from `message[key]`, three finite numbers."""
    value = message.get(key)
    ok = isinstance(value, list | tuple) and len(value) == 3
    ok = ok and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    if not ok or not all(math.isfinite(v) for v in value):
        raise ProtocolError(
            f"'{key}' must be three finite numbers [x, y, theta], got {_brief(value)}"
        )
    return np.array(value, dtype=np.float64)


def number(message: dict[str, Any], key: str, *, positive: bool = False) -> float:
    value = message.get(key)
    if not isinstance(value, int | float) or isinstance(value, bool) or not math.isfinite(value):
        raise ProtocolError(f"'{key}' must be a finite number, got {_brief(value)}")
    if positive and value <= 0:
        raise ProtocolError(f"'{key}' must be positive, got {value}")
    return float(value)


def count(message: dict[str, Any], key: str) -> int:
    value = message.get(key)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise ProtocolError(f"'{key}' must be a whole number >= 0, got {_brief(value)}")
    return value


def cells(data: Any, encoding: str, height: int, width: int, where: str) -> np.ndarray:
    """(height, width) float32 probabilities from a map's or patch's `data` bytes, NaN unknown:
    float32 as is (NaN or negative = unknown), int8 as ROS's OccupancyGrid (0-100, -1)."""
    out = np.empty((height, width), dtype=np.float32)
    cells_into(out, data, encoding, where)
    return out


def cells_into(out: np.ndarray, data: Any, encoding: str, where: str) -> None:
    """Check `data` (the cells of `out`'s shape, see `cells`) and write them into `out`, a
    float32 array or view, in place: one copy, no temporary grid (`out` is partly written
    when a value is refused: see check_cells_data to check first)."""
    raw = _raw(data, encoding, out.shape, where)
    if encoding == "int8":
        if copy_int8(raw, out):
            raise ProtocolError(f"{where} int8 cells {_RANGES['int8']}")
        return
    if copy_float32(raw, out):
        raise ProtocolError(f"{where} float32 cells {_RANGES['float32']}")


def check_cells_data(data: Any, encoding: str, shape: tuple[int, int], where: str) -> None:
    """ProtocolError unless `data` holds `shape` cells that cells_into takes, writing nothing."""
    raw = _raw(data, encoding, shape, where)
    if check_cells(raw.reshape(-1), encoding == "int8"):
        raise ProtocolError(f"{where} {encoding} cells {_RANGES[encoding]}")


_RANGES = {"int8": "must be -1 or 0..100", "float32": "must be probabilities in [0, 1] or NaN"}


def _raw(data: Any, encoding: str, shape: tuple[int, int], where: str) -> np.ndarray:
    """`data` as a read-only (H, W) array of `encoding` (ProtocolError: not that many bytes)."""
    height, width = shape
    dtype = ENCODINGS[encoding]
    if not isinstance(data, bytes) or len(data) != height * width * dtype.itemsize:
        size = len(data) if isinstance(data, bytes) else type(data).__name__
        need = height * width * dtype.itemsize
        raise ProtocolError(f"{where} 'data' must be {need} bytes of {encoding}, got {size}")
    return np.frombuffer(data, dtype=dtype).reshape(height, width)


def scatter_into(flat: np.ndarray, index: Any, data: Any, encoding: str, where: str) -> None:
    """Check a cell list (version 2: `index`, K uint32 little-endian flat indices row * width
    + col; `data`, K cells in `encoding`) and write it into the flat float32 map `flat` in
    place; ProtocolError, naming `where`, on anything malformed (then nothing is written)."""
    dtype = ENCODINGS[encoding]
    if not isinstance(index, bytes) or len(index) % 4:
        size = len(index) if isinstance(index, bytes) else type(index).__name__
        raise ProtocolError(f"{where} 'index' must be bytes of uint32, got {size}")
    k = len(index) // 4
    if not isinstance(data, bytes) or len(data) != k * dtype.itemsize:
        size = len(data) if isinstance(data, bytes) else type(data).__name__
        need = k * dtype.itemsize
        raise ProtocolError(f"{where} 'data' must be {need} bytes of {encoding}, got {size}")
    idx = np.frombuffer(index, dtype="<u4")
    raw = np.frombuffer(data, dtype=dtype)
    status = scatter(idx, raw, flat, encoding == "int8")
    if status == BAD_INDEX:
        raise ProtocolError(f"{where} 'index' holds a cell past the map's {flat.shape[0]} cells")
    if status:
        raise ProtocolError(f"{where} {encoding} cells {_RANGES[encoding]}")


def _brief(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."
