"""Live progress of a running run: stored on the run at a modest rate, published on Redis
pub/sub for viewers at a bounded rate, and the place where a cancellation is noticed.

Wire format (one JSON object per message on `mapqual:run:<id>`):
  progress  the light figures the database stores too (simulated time, coverage, poses, ...)
  seq       message counter of this run
  and, only while somebody listens (PUBLISH answers with the number of listeners):
  path      {"i0": index of the first point sent, "gt": [[x, y], ...], "est": [[x, y], ...]}:
            the new path points since the last message (all of them after a new listener came)
  scan      [[x, y], ...] [m] the latest scan's end points in the world frame (true pose)
  goal      [x, y] [m] the current frontier goal (or null), plan [[x, y], ...] the global plan
  map       a changed rectangle of the SLAM map (see `encode_map_patch`), at most once every
            `map_every_s`; the whole map after a new listener came or when the map grew.
"""

from __future__ import annotations

import base64
import json
import time
import zlib
from typing import Any

import numpy as np
from sqlalchemy import select, true, update

from backend.db.models import Run, utcnow
from backend.db.session import get_engine
from worker.pipeline import RunCancelled, RunProgress, RunSuperseded

# map cell codes on the wire
UNKNOWN, FREE, OCCUPIED = 0, 1, 2
SCAN_POINTS = 180  # at most this many scan points per message
PLAN_POINTS = 200  # at most this many plan points per message


def channel(run_id: int) -> str:
    """The pub/sub channel of one run."""
    return f"mapqual:run:{run_id}"


def map_codes(grid: Any) -> np.ndarray:
    """(H, W) uint8 UNKNOWN / FREE / OCCUPIED of an OccupancyGrid, `[iy, ix]` bottom row first."""
    prob = grid.prob
    codes = np.full(prob.shape, FREE, dtype=np.uint8)
    with np.errstate(invalid="ignore"):
        codes[prob > grid.occ_thresh] = OCCUPIED
    codes[np.isnan(prob)] = UNKNOWN
    return codes


def encode_map_patch(
    codes: np.ndarray, box: tuple[int, int, int, int], resolution: float, origin, full: bool
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


def decode_map_patch(msg: dict[str, Any]) -> tuple[tuple[int, int, int, int], np.ndarray]:
    """(box, (h, w) uint8 codes) of an `encode_map_patch` message."""
    iy0, ix0, h, w = (int(v) for v in msg["box"])
    raw = zlib.decompress(base64.b64decode(msg["data"]))
    return (iy0, ix0, h, w), np.frombuffer(raw, dtype=np.uint8).reshape(h, w)


def changed_box(old: np.ndarray, new: np.ndarray) -> tuple[int, int, int, int] | None:
    """The bounding box (iy0, ix0, h, w) of the cells that differ, or None."""
    diff = old != new
    rows = np.flatnonzero(diff.any(axis=1))
    if len(rows) == 0:
        return None
    cols = np.flatnonzero(diff.any(axis=0))
    return int(rows[0]), int(cols[0]), int(rows[-1] - rows[0] + 1), int(cols[-1] - cols[0] + 1)


def _xy(points: np.ndarray, decimals: int = 3) -> list[list[float]]:
    return np.round(np.asarray(points, dtype=float)[:, :2], decimals).tolist()


def _thin(points: np.ndarray, most: int) -> np.ndarray:
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


class ProgressReporter:
    """The `on_progress` callback of a run executed by a worker.

    Every `store_every_s` of wall time it writes the progress and a heartbeat to the run's
    row, on condition that the run is still running under `attempt` (any attempt if None): a
    run cancelled meanwhile raises `RunCancelled`, one taken over by another attempt (or put
    back to queued) `RunSuperseded`, either of which stops it at its next step. Every
    `publish_every_s` it publishes the progress on the run's channel (every
    `idle_publish_every_s` while nobody listens); path points, scan, plan and map go out only
    while somebody listens, the map at most every `map_every_s`.
    """

    def __init__(
        self,
        database_url: str,
        run_id: int,
        redis_client: Any | None = None,
        attempt: str | None = None,
        store_every_s: float = 2.0,
        publish_every_s: float = 0.2,
        map_every_s: float = 1.0,
        idle_publish_every_s: float = 1.0,
    ):
        self.url = database_url
        self.run_id = run_id
        self.redis = redis_client
        self.attempt = attempt
        self.store_every_s = store_every_s
        self.publish_every_s = publish_every_s
        self.map_every_s = map_every_s
        self.idle_publish_every_s = idle_publish_every_s
        self._next_store = 0.0
        self._next_publish = 0.0
        self._next_map = 0.0
        self._path = np.empty((1024, 4))  # gt x, y, est x, y per progress call
        self._n = 0
        self._sent = 0  # path points the listeners have
        self._listeners = 0
        self._map: np.ndarray | None = None  # the codes the listeners have
        self._map_key: tuple | None = None  # (shape, origin) of those codes
        self._seq = 0

    @staticmethod
    def payload(p: RunProgress) -> dict[str, Any]:
        """The light progress figures (stored on the run and sent in every message)."""
        return {
            "t": round(p.t, 3),
            "coverage": round(p.coverage, 4),
            "pose_gt": [round(float(v), 4) for v in p.pose_gt],
            "pose_est": [round(float(v), 4) for v in p.pose_est],
            "status": p.status,
            "goals_reached": p.goals_reached,
            "rtf": round(p.rtf, 2),
        }

    def __call__(self, p: RunProgress) -> None:
        self._record(p)
        now = time.monotonic()
        if self.redis is not None and now >= self._next_publish:
            try:
                self._publish(p, now)
            except Exception:  # a viewer feed must never break a run
                self.redis = None
            # nobody listening: only often enough to notice a new listener soon
            period = self.publish_every_s if self._listeners else self.idle_publish_every_s
            self._next_publish = now + period
        if now >= self._next_store:
            self._next_store = now + self.store_every_s
            self._store(p)

    def _store(self, p: RunProgress) -> None:
        """One statement: the progress and a heartbeat, while this attempt holds the run."""
        held = Run.attempt == self.attempt if self.attempt is not None else true()
        stmt = (
            update(Run)
            .where(Run.id == self.run_id, Run.status == "running", held)
            .values(progress=self.payload(p), heartbeat_at=utcnow())
            .returning(Run.id)
        )
        with get_engine(self.url).begin() as conn:
            if conn.execute(stmt).first() is not None:
                return
            status = conn.scalar(select(Run.status).where(Run.id == self.run_id))
        if status in (None, "cancelled"):
            raise RunCancelled(f"run {self.run_id} was cancelled (or deleted)")
        raise RunSuperseded(f"run {self.run_id} is no longer held by attempt {self.attempt}")

    def _record(self, p: RunProgress) -> None:
        if self._n == len(self._path):
            self._path = np.concatenate([self._path, np.empty_like(self._path)])
        self._path[self._n, :2] = p.pose_gt[:2]
        self._path[self._n, 2:] = p.pose_est[:2]
        self._n += 1

    def _publish(self, p: RunProgress, now: float) -> None:
        msg: dict[str, Any] = {"progress": self.payload(p), "seq": self._seq}
        self._seq += 1
        if self._listeners > 0:
            msg.update(self._live(p, now))
        n = int(self.redis.publish(channel(self.run_id), json.dumps(msg, separators=(",", ":"))))
        if n > self._listeners:  # somebody new: the next message starts from scratch
            self._sent, self._map, self._next_map = 0, None, 0.0
        self._listeners = n

    def _live(self, p: RunProgress, now: float) -> dict[str, Any]:
        """What only listeners need: new path points, scan, goal and plan, a map patch."""
        path = self._path[self._sent : self._n]
        out: dict[str, Any] = {
            "path": {"i0": self._sent, "gt": _xy(path[:, :2]), "est": _xy(path[:, 2:])},
            "goal": None if p.goal_xy is None else _xy(np.reshape(p.goal_xy, (1, 2)))[0],
            "plan": None if p.plan is None else _xy(_thin(np.asarray(p.plan), PLAN_POINTS)),
        }
        self._sent = self._n
        if p.ranges is not None and p.beam_angles is not None:
            out["scan"] = _xy(scan_points(p), 2)
        if p.occupancy is not None and now >= self._next_map:
            self._next_map = now + self.map_every_s
            patch = self._map_patch(p.occupancy())
            if patch is not None:
                out["map"] = patch
        return out

    def _map_patch(self, grid: Any) -> dict[str, Any] | None:
        codes = map_codes(grid)
        key = (codes.shape, tuple(np.round(grid.origin, 6)))
        if self._map is None or key != self._map_key:
            box, full = (0, 0, codes.shape[0], codes.shape[1]), True
        else:
            box, full = changed_box(self._map, codes), False
            if box is None:
                return None
        self._map, self._map_key = codes, key
        return encode_map_patch(codes, box, grid.resolution, grid.origin, full)
