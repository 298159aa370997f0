"""Live progress of a running run: stored on the run at a modest rate, published on Redis
pub/sub for viewers at a bounded rate, and the place where a cancellation is noticed."""

from __future__ import annotations

import json
import time
from typing import Any

from backend.db.models import Run
from backend.db.session import session_scope
from worker.pipeline import RunCancelled, RunProgress


def channel(run_id: int) -> str:
    """The pub/sub channel of one run."""
    return f"mapqual:run:{run_id}"


class ProgressReporter:
    """The `on_progress` callback of a run executed by a worker.

    Every `store_every_s` of wall time it writes the progress to the run's row and reads the
    run's status back: a run cancelled meanwhile raises `RunCancelled`, which stops it at its
    next step. Every `publish_every_s` it publishes the progress on the run's channel.
    """

    def __init__(
        self,
        database_url: str,
        run_id: int,
        redis_client: Any | None = None,
        store_every_s: float = 2.0,
        publish_every_s: float = 0.2,
    ):
        self.url = database_url
        self.run_id = run_id
        self.redis = redis_client
        self.store_every_s = store_every_s
        self.publish_every_s = publish_every_s
        self._next_store = 0.0
        self._next_publish = 0.0

    @staticmethod
    def payload(p: RunProgress) -> dict[str, Any]:
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
        now = time.monotonic()
        if self.redis is not None and now >= self._next_publish:
            self._next_publish = now + self.publish_every_s
            try:
                self.redis.publish(channel(self.run_id), json.dumps({"progress": self.payload(p)}))
            except Exception:  # a viewer feed must never break a run
                self.redis = None
        if now >= self._next_store:
            self._next_store = now + self.store_every_s
            with session_scope(self.url) as s:
                run = s.get_one(Run, self.run_id)
                if run.status == "cancelled":
                    raise RunCancelled(f"run {self.run_id} was cancelled")
                run.progress = self.payload(p)
