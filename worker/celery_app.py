"""The one Celery app and all of its configuration (tasks in `worker.tasks`)."""

from __future__ import annotations

import os

from celery import Celery

REDIS_URL = os.environ.get("REDIS_URL", "redis://127.0.0.1:6379/0")
# A run is minutes of CPU: the hard limit kills a runaway task, the soft one lets it store why.
SOFT_TIME_LIMIT_S = int(os.environ.get("MAPQUAL_TASK_SOFT_TIME_LIMIT", "7200"))
HARD_TIME_LIMIT_S = int(os.environ.get("MAPQUAL_TASK_TIME_LIMIT", "7500"))
# Redis redelivers a message that no worker acknowledged after this long (a worker died
# mid-run, since tasks are acknowledged late). It should exceed the longest run: a message
# redelivered while its run's attempt is alive only comes back later (the run's lease,
# MAPQUAL_RUN_LEASE, decides when an attempt is dead), and one result is kept in any case.
VISIBILITY_TIMEOUT_S = int(
    os.environ.get("MAPQUAL_VISIBILITY_TIMEOUT", str(HARD_TIME_LIMIT_S + 300))
)

app = Celery("mapqual", broker=REDIS_URL, include=["worker.tasks"])
app.conf.update(
    task_serializer="json",
    accept_content=["json"],
    result_serializer="json",
    # Results live in the database, keyed by run id; Celery keeps none.
    task_ignore_result=True,
    result_backend=None,
    # One run at a time per worker process: a run is long, prefetching would starve others.
    worker_prefetch_multiplier=1,
    # Acknowledge after the run, and requeue when the worker process dies: at-least-once
    # delivery, which the run task's compare-and-set claim turns into exactly one result.
    task_acks_late=True,
    task_reject_on_worker_lost=True,
    task_soft_time_limit=SOFT_TIME_LIMIT_S,
    task_time_limit=HARD_TIME_LIMIT_S,
    broker_transport_options={
        "visibility_timeout": VISIBILITY_TIMEOUT_S,
        # sweep for abandoned messages often enough to honour a short visibility timeout
        "unacked_restore_interval": max(1, min(10, VISIBILITY_TIMEOUT_S // 4)),
        "unacked_restore_throttle": 1,
        # A worker killed during a sweep leaves the sweep's mutex held until it expires (kombu's
        # default: 300 s), and nobody restores anything meanwhile; a sweep takes milliseconds.
        "unacked_mutex_expire": max(5, min(300, VISIBILITY_TIMEOUT_S // 2)),
    },
    broker_connection_retry_on_startup=True,
    worker_send_task_events=False,
    task_default_queue="mapqual",
    timezone="UTC",
)
