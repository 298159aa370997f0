"""An estimate's `map`: a whole occupancy grid, or patches or (version 2) a list of cells laid
over the previous one."""

from __future__ import annotations

from typing import Any

import numpy as np

from worker.slam.external.protocol import (
    ENCODINGS,
    MAX_FRAME,
    ProtocolError,
    cells,
    cells_into,
    check_cells_data,
    count,
    number,
    scatter_into,
)
from worker.slam.grid import OccupancyGrid

MAX_MAP_CELLS = MAX_FRAME  # the largest map a frame can carry whole (int8: a byte a cell)


def read_map(
    m: Any,
    previous: OccupancyGrid | None,
    occ_thresh: float,
    *,
    version: int = 1,
    reuse: bool = False,
) -> OccupancyGrid:
    """The grid an estimate's `map` describes (`previous`: the last one, for patches and cells;
    `version`: the protocol's, which says whether `cells` may come). reuse=True: nobody but the
    caller holds `previous` or its cells, and a map of the same extent is written into them in
    place (no copy of the whole grid); `previous` must not be used afterwards."""
    if not isinstance(m, dict):
        raise ProtocolError(f"'map' must be a map, got {type(m).__name__}")
    resolution = number(m, "resolution", positive=True)
    origin = m.get("origin")
    if not (isinstance(origin, list | tuple) and len(origin) == 2):
        raise ProtocolError("map 'origin' must be two numbers [x, y] [m]")
    origin_xy = np.array([number({"x": v}, "x") for v in origin])
    width, height = count(m, "width"), count(m, "height")
    if width * height > MAX_MAP_CELLS:  # patches or cells would make mapqual allocate it
        raise ProtocolError(
            f"a map of {width} x {height} cells is larger than mapqual takes "
            f"({MAX_MAP_CELLS} cells, a whole int8 map in one frame)"
        )
    encoding = m.get("encoding", "float32")
    if encoding not in ENCODINGS:
        raise ProtocolError(f"map 'encoding' must be one of {sorted(ENCODINGS)}, not {encoding!r}")
    if "data" in m:
        prob = cells(m["data"], encoding, height, width, "map")
    elif isinstance(m.get("patches"), list):
        # every patch checked before any is written: a refused map leaves `previous` whole
        boxes = [
            _box(p, height, width, encoding, f"map patch {i}") for i, p in enumerate(m["patches"])
        ]
        prob = placed(previous, resolution, origin_xy, height, width, reuse)
        for (row, col, h, w), patch in zip(boxes, m["patches"], strict=True):
            cells_into(prob[row : row + h, col : col + w], patch["data"], encoding, "map patch")
    elif isinstance(m.get("cells"), dict):
        if version < 2:
            raise ProtocolError("map 'cells' needs protocol version 2 (this program chose 1)")
        prob = placed(previous, resolution, origin_xy, height, width, reuse)
        c = m["cells"]
        try:  # the kernel checks every cell before it writes one
            scatter_into(prob.reshape(-1), c.get("index"), c.get("data"), encoding, "map cells")
        except ProtocolError:
            if previous is not None and prob is previous.prob:
                prob.setflags(write=False)  # refused: the previous map stays as it was
            raise
    else:
        forms = "'data' (the whole grid) or 'patches' (a list)"
        forms += ", or 'cells' (version 2)" if version >= 2 else ""
        raise ProtocolError(f"a map needs {forms}")
    return OccupancyGrid.adopt(prob, resolution, origin_xy, occ_thresh)  # prob is ours alone


def _box(patch: Any, height: int, width: int, encoding: str, where: str) -> tuple[int, ...]:
    """(row, col, h, w) of one patch {col, row, width, height, data} of a `height` x `width`
    map, its data checked (ProtocolError naming `where`); nothing written."""
    if not isinstance(patch, dict):
        raise ProtocolError(f"{where} must be a map")
    col, row = count(patch, "col"), count(patch, "row")
    w, h = count(patch, "width"), count(patch, "height")
    if row + h > height or col + w > width:
        raise ProtocolError(
            f"{where} ({col}, {row}) + ({w} x {h}) leaves the {width} x {height} map"
        )
    check_cells_data(patch.get("data"), encoding, (h, w), where)
    return row, col, h, w


def placed(
    previous: OccupancyGrid | None,
    resolution: float,
    origin: np.ndarray,
    height: int,
    width: int,
    reuse: bool = False,
) -> np.ndarray:
    """(height, width) float32, writable and C-contiguous: the previous grid's cells moved into
    the new extent, NaN elsewhere (a map that grew keeps its resolution and moves by whole
    cells). reuse=True: the previous cells themselves when the extent is the same (see
    read_map), else a copy."""
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
    if (dx, dy, ph, pw) == (0, 0, height, width):  # the same extent
        if reuse and _writable_again(previous.prob):
            return previous.prob
        return previous.prob.copy()
    prob = np.full((height, width), np.nan, dtype=np.float32)
    x0, y0 = max(dx, 0), max(dy, 0)
    x1, y1 = min(dx + pw, width), min(dy + ph, height)
    if x1 > x0 and y1 > y0:
        prob[y0:y1, x0:x1] = previous.prob[y0 - dy : y1 - dy, x0 - dx : x1 - dx]
    return prob


def _writable_again(prob: np.ndarray) -> bool:
    """Make an adopted grid's cells writable again; False (left as they are) unless they are a
    C-contiguous float32 array owning its memory (numpy refuses the flag otherwise)."""
    if prob.base is not None or prob.dtype != np.float32 or not prob.flags.c_contiguous:
        return False
    try:
        prob.setflags(write=True)
    except ValueError:
        return False
    return True
