"""Celery tasks: thin shells that load a run, call `pipeline.run_one`, and persist.

The work itself (claim, run, store exactly once) is `backend.execute.execute_run`; this module
is the one place in worker/ that imports backend.
"""

from __future__ import annotations

import logging
from typing import Any

from celery import Task
from celery.signals import worker_process_init

from backend.core.config import get_settings
from worker.celery_app import configure
from worker.celery_conf import RUN_TASK

log = logging.getLogger("mapqual.tasks")
app = configure(get_settings().redis_url, get_settings().task_limits())


@app.task(name=RUN_TASK, bind=True, acks_late=True, reject_on_worker_lost=True, max_retries=None)
def run_task(self: Task, run_id: int) -> str:
    """Execute one stored run exactly once. A delivery that finds another attempt alive comes
    back later (no retry cap), so that the run is finished even if that attempt dies; one
    that finds the run done, cancelled or failed does nothing."""
    from backend.execute import execute_run

    settings = get_settings()
    outcome = execute_run(run_id, settings, _redis(settings.redis_url))
    if outcome.kind == "busy":
        # well within the visibility timeout: Redis would redeliver a longer countdown's
        # message (held unacknowledged by the worker) before it is due
        raise self.retry(countdown=max(1.0, settings.run_lease_s / 2), max_retries=None)
    return outcome.message


@worker_process_init.connect
def _start_sweeper(**_: Any) -> None:
    """Each worker process sweeps for runs whose message a restarted broker lost."""
    from backend.recovery import start_sweeper

    settings = get_settings()
    start_sweeper(settings.database_url, settings.redis_url, settings.run_lease_s)


def _redis(url: str) -> Any:
    """A Redis client for the live feed, or None when Redis is away (the run goes on)."""
    import redis

    try:
        client = redis.Redis.from_url(url, socket_connect_timeout=1, socket_timeout=1)
        client.ping()
        return client
    except Exception:
        log.warning("no Redis at %s: live progress is not published", url)
        return None
