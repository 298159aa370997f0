"""The backend's side of the Celery worker: the run service (`execute_run`) and the sweeper,
registered with `worker.tasks` (which imports no backend) before the worker starts."""

from __future__ import annotations

import logging
from dataclasses import dataclass

from celery import Celery
from redis import Redis

from backend.core.config import Settings, get_settings
from worker.tasks import serve

log = logging.getLogger("mapqual.tasks")


@dataclass(frozen=True)
class BackendHost:
    """`worker.tasks.RunHost` over the database, storage and Redis of `settings`."""

    settings: Settings

    @property
    def retry_after_s(self) -> float:
        return max(1.0, self.settings.run_lease_s / 2)  # [s]

    def execute(self, run_id: int) -> tuple[bool, str]:
        from backend.services.execute import execute_run

        outcome = execute_run(run_id, self.settings, live_redis(self.settings.redis_url))
        return outcome.kind == "busy", outcome.message

    def start_process(self) -> None:
        from backend.services.sweeper import start_sweeper

        s = self.settings
        start_sweeper(s.database_url, s.redis_url, s.run_lease_s)


def install(settings: Settings | None = None) -> Celery:
    """The worker's Celery app, configured from `settings`, its run task served by the backend."""
    settings = settings or get_settings()
    return serve(BackendHost(settings), settings.redis_url, settings.task_limits())


def live_redis(url: str) -> Redis | None:
    """A Redis client for the live feed, or None when Redis is away (the run goes on)."""
    try:
        client = Redis.from_url(url, socket_connect_timeout=1, socket_timeout=1)
        client.ping()
        return client
    except Exception:
        log.warning("no Redis at %s: live progress is not published", url)
        return None
