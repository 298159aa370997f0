"""The live feed's wire format: what a worker publishes on Redis and the viewer decodes.

One JSON object per message on `channel(run_id)` = `mapqual:run:<id>`:
  progress  the light figures the database stores too (`progress_payload`: simulated time,
            coverage, poses, ...; under real-time SLAM emulation also `realtime`: updates,
            scans dropped and latencies so far)
  seq       message counter of this run
  and, only while somebody listens (PUBLISH answers with the number of listeners):
  path      {"i0": index of the first point sent, "gt": [[x, y], ...], "est": [[x, y], ...]}:
            the new path points since the last message (all of them after a new listener came)
  scan      [[x, y], ...] [m] the latest scan's end points in the world frame (true pose)
  goal      [x, y] [m] the current frontier goal (or null), plan [[x, y], ...] the global plan
  map       a changed rectangle of the SLAM map in cell codes (see `encode_map_patch`); the
            whole map after a new listener came or when the map grew.

numpy only (no numba, no database): the worker, the backend and the viewer all import it.
"""

from __future__ import annotations

import base64
import zlib
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from worker.pipeline import RunProgress

# map cell codes on the wire
UNKNOWN, FREE, OCCUPIED = 0, 1, 2
SCAN_POINTS = 180  # at most this many scan points per message
PLAN_POINTS = 200  # at most this many plan points per message
ROS_OCCUPIED = 65  # a stored ROS grid's cell is occupied from this value up (map_saver)

Box = tuple[int, int, int, int]  # (iy0, ix0, h, w) [cells] a rectangle of a map


def channel(run_id: int) -> str:
    """The pub/sub channel of one run."""
    return f"mapqual:run:{run_id}"


def progress_payload(p: RunProgress) -> dict[str, Any]:
    """The light progress figures (stored on the run and sent in every message)."""
    return {
        "t": round(p.t, 3),
        "coverage": round(p.coverage, 4),
        "pose_gt": [round(float(v), 4) for v in p.pose_gt],
        "pose_est": [round(float(v), 4) for v in p.pose_est],
        "status": p.status,
        "goals_reached": p.goals_reached,
        "rtf": round(p.rtf, 2),
        **({} if p.realtime is None else {"realtime": _realtime_figures(p.realtime)}),
    }


def _realtime_figures(rt: dict[str, Any]) -> dict[str, Any]:
    """A real-time run's counters so far (worker.slam.realtime), latencies to the ms."""
    out = {k: rt[k] for k in ("speed", "fixed_latency_s", "scans", "updates", "scans_dropped")}
    out.update({k: round(float(rt[k]), 3) for k in ("latency_mean_s", "latency_max_s")})
    return out


def map_codes(grid: Any) -> np.ndarray:
    """(H, W) uint8 UNKNOWN / FREE / OCCUPIED of an OccupancyGrid, `[iy, ix]` bottom row first."""
    prob = grid.prob
    codes = np.full(prob.shape, FREE, dtype=np.uint8)
    with np.errstate(invalid="ignore"):
        codes[prob > grid.occ_thresh] = OCCUPIED
    codes[np.isnan(prob)] = UNKNOWN
    return codes


def ros_codes(grid_ros: np.ndarray) -> np.ndarray:
    """A stored ROS grid (-1 unknown, 0..100) as cell codes; occupied from 65 (map_saver)."""
    occupied = np.where(grid_ros >= ROS_OCCUPIED, OCCUPIED, FREE)
    return np.where(grid_ros < 0, UNKNOWN, occupied).astype(np.uint8)


def encode_map_patch(
    codes: np.ndarray, box: Box, resolution: float, origin: Any, full: bool
) -> dict[str, Any]:
    """A rectangle `box = (iy0, ix0, h, w)` of the map codes, zlib-compressed and base64'd.

    `shape` and `origin` describe the whole map, so a receiver can (re)allocate it.
    """
    iy0, ix0, h, w = box
    patch = np.ascontiguousarray(codes[iy0 : iy0 + h, ix0 : ix0 + w])
    return {
        "full": full,
        "shape": [int(codes.shape[0]), int(codes.shape[1])],
        "resolution": float(resolution),
        "origin": [round(float(origin[0]), 6), round(float(origin[1]), 6)],
        "box": [int(iy0), int(ix0), int(h), int(w)],
        "data": base64.b64encode(zlib.compress(patch.tobytes(), 1)).decode("ascii"),
    }


def decode_map_patch(msg: dict[str, Any]) -> tuple[Box, np.ndarray]:
    """(box, (h, w) uint8 codes) of an `encode_map_patch` message."""
    iy0, ix0, h, w = (int(v) for v in msg["box"])
    raw = zlib.decompress(base64.b64decode(msg["data"]))
    return (iy0, ix0, h, w), np.frombuffer(raw, dtype=np.uint8).reshape(h, w)


def changed_box(old: np.ndarray, new: np.ndarray) -> Box | None:
    """The bounding box (iy0, ix0, h, w) of the cells that differ, or None."""
    diff = old != new
    rows = np.flatnonzero(diff.any(axis=1))
    if len(rows) == 0:
        return None
    cols = np.flatnonzero(diff.any(axis=0))
    return int(rows[0]), int(cols[0]), int(rows[-1] - rows[0] + 1), int(cols[-1] - cols[0] + 1)


def xy(points: np.ndarray, decimals: int = 3) -> list[list[float]]:
    """(K, >= 2) points as the wire's [[x, y], ...], rounded to `decimals`."""
    return np.round(np.asarray(points, dtype=float)[:, :2], decimals).tolist()


def thin(points: np.ndarray, most: int) -> np.ndarray:
    """At most `most` points, evenly spaced, the last one kept."""
    if len(points) <= most:
        return points
    idx = np.unique(np.linspace(0, len(points) - 1, most).round().astype(int))
    return points[idx]


def scan_points(p: RunProgress) -> np.ndarray:
    """(K, 2) [m] end points of the scan's returns in the world frame, seen from the true pose."""
    ranges = np.asarray(p.ranges, dtype=float)
    angles = np.asarray(p.beam_angles, dtype=float)
    ok = np.isfinite(ranges) & (ranges < p.range_max)
    step = max(1, int(np.ceil(ok.sum() / SCAN_POINTS)))
    r, a = ranges[ok][::step], angles[ok][::step] + p.pose_gt[2]
    return np.column_stack((p.pose_gt[0] + r * np.cos(a), p.pose_gt[1] + r * np.sin(a)))


def points(data: Any) -> np.ndarray:
    """The wire's [[x, y], ...] as a (K, 2) float array (K = 0 for an empty list)."""
    return np.asarray(data, dtype=float).reshape(-1, 2)
