"""Celery's names and settings in one place: the run task's name, its queue, and the
configuration of the worker's app and of the producers' (the API, `mapqual batch --celery`).

Plain values only (no Celery, no kernels, no backend): the values that are settings come in as
arguments, from `backend.core.config.Settings`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

RUN_TASK = "mapqual.run"  # the one task: execute one stored run (worker.tasks.run_task)
QUEUE = "mapqual"  # the one queue, a Redis list of that name

# Both ends speak JSON on the one queue.
_WIRE: dict[str, Any] = {
    "task_serializer": "json",
    "accept_content": ["json"],
    "task_default_queue": QUEUE,
}


@dataclass(frozen=True)
class TaskLimits:
    """How long a run's task may take, and when Redis gives its message to another worker."""

    # A run is minutes of CPU: the hard limit kills a runaway task, the soft one lets it store why.
    soft_s: int = 7200  # [s]
    hard_s: int = 7500  # [s]
    # Redis redelivers a message that no worker acknowledged after this long (a worker died
    # mid-run, since tasks are acknowledged late). It should exceed the longest run: a message
    # redelivered while its run's attempt is alive only comes back later (the run's lease
    # decides when an attempt is dead), and one result is kept in any case. None: hard_s + 300.
    visibility_s: int | None = None  # [s]

    @property
    def visibility_timeout_s(self) -> int:
        """The visibility timeout in force [s]."""
        return self.visibility_s if self.visibility_s is not None else self.hard_s + 300


def worker_conf(broker_url: str, limits: TaskLimits) -> dict[str, Any]:
    """The worker app's whole configuration."""
    visibility = limits.visibility_timeout_s
    return {
        **_WIRE,
        "broker_url": broker_url,
        "result_serializer": "json",
        # Results live in the database, keyed by run id; Celery keeps none.
        "task_ignore_result": True,
        "result_backend": None,
        # One run at a time per worker process: a run is long, prefetching would starve others.
        "worker_prefetch_multiplier": 1,
        # Acknowledge after the run, and requeue when the worker process dies: at-least-once
        # delivery, which the run task's compare-and-set claim turns into exactly one result.
        "task_acks_late": True,
        "task_reject_on_worker_lost": True,
        "task_soft_time_limit": limits.soft_s,
        "task_time_limit": limits.hard_s,
        "broker_transport_options": {
            "visibility_timeout": visibility,
            # sweep for abandoned messages often enough to honour a short visibility timeout
            "unacked_restore_interval": max(1, min(10, visibility // 4)),
            "unacked_restore_throttle": 1,
            # A worker killed during a sweep leaves the sweep's mutex held until it expires
            # (kombu's default: 300 s), and nobody restores anything meanwhile; a sweep takes
            # milliseconds.
            "unacked_mutex_expire": max(5, min(300, visibility // 2)),
        },
        "broker_connection_retry_on_startup": True,
        "worker_send_task_events": False,
        "timezone": "UTC",
    }


def producer_conf(broker_url: str) -> dict[str, Any]:
    """A producer's configuration: the worker's wire format, and a broker that cannot be
    reached fails the send at once (the API answers 503) instead of retrying."""
    return {
        **_WIRE,
        "broker_url": broker_url,
        "broker_connection_retry": False,
        "broker_connection_max_retries": 0,
        "broker_transport_options": {"socket_connect_timeout": 2, "socket_timeout": 5},
    }
