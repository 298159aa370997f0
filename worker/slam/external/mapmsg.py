"""An estimate's `map`: a whole occupancy grid, or patches laid over the previous one."""

from __future__ import annotations

from typing import Any

import numpy as np

from worker.slam.external.protocol import ENCODINGS, ProtocolError, cells, cells_into, count, number
from worker.slam.grid import OccupancyGrid


def read_map(m: Any, previous: OccupancyGrid | None, occ_thresh: float) -> OccupancyGrid:
    """The grid an estimate's `map` describes (`previous`: the last one, for patches)."""
    if not isinstance(m, dict):
        raise ProtocolError(f"'map' must be a map, got {type(m).__name__}")
    resolution = number(m, "resolution", positive=True)
    origin = m.get("origin")
    if not (isinstance(origin, list | tuple) and len(origin) == 2):
        raise ProtocolError("map 'origin' must be two numbers [x, y] [m]")
    origin_xy = np.array([number({"x": v}, "x") for v in origin])
    width, height = count(m, "width"), count(m, "height")
    encoding = m.get("encoding", "float32")
    if encoding not in ENCODINGS:
        raise ProtocolError(f"map 'encoding' must be one of {sorted(ENCODINGS)}, not {encoding!r}")
    if "data" in m:
        prob = cells(m["data"], encoding, height, width, "map")
    elif isinstance(m.get("patches"), list):
        prob = _placed(previous, resolution, origin_xy, height, width)
        for i, patch in enumerate(m["patches"]):
            _lay(prob, patch, encoding, f"map patch {i}")
    else:
        raise ProtocolError("a map needs 'data' (the whole grid) or 'patches' (a list)")
    return OccupancyGrid.adopt(prob, resolution, origin_xy, occ_thresh)  # prob is ours alone


def _lay(prob: np.ndarray, patch: Any, encoding: str, where: str) -> None:
    """Write one patch {col, row, width, height, data} into `prob` in place."""
    if not isinstance(patch, dict):
        raise ProtocolError(f"{where} must be a map")
    col, row = count(patch, "col"), count(patch, "row")
    w, h = count(patch, "width"), count(patch, "height")
    if row + h > prob.shape[0] or col + w > prob.shape[1]:
        raise ProtocolError(
            f"{where} ({col}, {row}) + ({w} x {h}) leaves the {prob.shape[1]} x {prob.shape[0]} map"
        )
    cells_into(prob[row : row + h, col : col + w], patch.get("data"), encoding, where)


def _placed(
    previous: OccupancyGrid | None, resolution: float, origin: np.ndarray, height: int, width: int
) -> np.ndarray:
    """(height, width) float32: the previous grid's cells moved into the new extent, NaN
    elsewhere (a map that grew keeps its resolution and moves by whole cells)."""
    if previous is None:
        return np.full((height, width), np.nan, dtype=np.float32)
    if previous.resolution != resolution:
        raise ProtocolError(
            f"map patches at resolution {resolution} m over a map of {previous.resolution} m: "
            "send the whole map when the resolution changes"
        )
    shift = (previous.origin - origin) / resolution  # [cells] where the old (0, 0) lands
    whole = np.round(shift)
    if np.any(np.abs(shift - whole) > 1e-6):
        raise ProtocolError("map patches: the map origin moved by a fraction of a cell")
    dx, dy = int(whole[0]), int(whole[1])
    ph, pw = previous.shape
    if (dx, dy, ph, pw) == (0, 0, height, width):  # the same extent: one copy
        return previous.prob.copy()
    prob = np.full((height, width), np.nan, dtype=np.float32)
    x0, y0 = max(dx, 0), max(dy, 0)
    x1, y1 = min(dx + pw, width), min(dy + ph, height)
    if x1 > x0 and y1 > y0:
        prob[y0:y1, x0:x1] = previous.prob[y0 - dy : y1 - dy, x0 - dx : x1 - dx]
    return prob
