"""Live progress of a running run: stored on the run at a modest rate, published on Redis
pub/sub for viewers at a bounded rate (in the wire format of `worker.live_wire`), and the
place where a cancellation is noticed."""

from __future__ import annotations

import json
import time
from typing import TYPE_CHECKING, Any

import numpy as np
from sqlalchemy import select, true, update

from backend.db.models import Run, utcnow
from backend.db.session import get_engine
from worker.live_wire import (
    PLAN_POINTS,
    changed_box,
    channel,
    encode_map_patch,
    map_codes,
    progress_payload,
    scan_points,
    thin,
    xy,
)
from worker.pipeline import RunCancelled, RunProgress, RunSuperseded
from worker.status import RunStatus

if TYPE_CHECKING:
    from redis import Redis


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
        redis_client: Redis | None = None,
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
            .where(Run.id == self.run_id, Run.status == RunStatus.RUNNING, held)
            .values(progress=progress_payload(p), heartbeat_at=utcnow())
            .returning(Run.id)
        )
        with get_engine(self.url).begin() as conn:
            if conn.execute(stmt).first() is not None:
                return
            status = conn.scalar(select(Run.status).where(Run.id == self.run_id))
        if status in (None, RunStatus.CANCELLED):
            raise RunCancelled(f"run {self.run_id} was cancelled (or deleted)")
        raise RunSuperseded(f"run {self.run_id} is no longer held by attempt {self.attempt}")

    def _record(self, p: RunProgress) -> None:
        if self._n == len(self._path):
            self._path = np.concatenate([self._path, np.empty_like(self._path)])
        self._path[self._n, :2] = p.pose_gt[:2]
        self._path[self._n, 2:] = p.pose_est[:2]
        self._n += 1

    def _publish(self, p: RunProgress, now: float) -> None:
        msg: dict[str, Any] = {"progress": progress_payload(p), "seq": self._seq}
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
            "path": {"i0": self._sent, "gt": xy(path[:, :2]), "est": xy(path[:, 2:])},
            "goal": None if p.goal_xy is None else xy(np.reshape(p.goal_xy, (1, 2)))[0],
            "plan": None if p.plan is None else xy(thin(np.asarray(p.plan), PLAN_POINTS)),
        }
        self._sent = self._n
        if p.ranges is not None and p.beam_angles is not None:
            out["scan"] = xy(scan_points(p), 2)
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
