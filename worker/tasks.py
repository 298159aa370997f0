"""Celery tasks: thin shells over the service that hosts the worker.

worker/ imports no backend: the run task calls a `RunHost`, which the process that starts the
worker registers with `serve` (the backend's `backend.services.worker_host.install`, used by
`mapqual worker`), together with the app's configuration. The host claims, runs and stores a
run exactly once.
"""

from __future__ import annotations

from typing import Any, Protocol

from celery import Celery, Task
from celery.signals import worker_process_init

from worker.celery_app import app, configure
from worker.celery_conf import RUN_TASK, TaskLimits
from worker.heap import release_free_heap


class RunHost(Protocol):
    """What a worker needs of the service that hosts it."""

    retry_after_s: float  # [s] when a delivery that found another attempt alive comes back

    def execute(self, run_id: int) -> tuple[bool, str]:
        """Run stored run `run_id` exactly once: (busy: another attempt holds the run, what
        became of this delivery)."""
        ...

    def start_process(self) -> None:
        """Start what each worker process keeps running beside its tasks (the sweeper)."""
        ...


_hosts: list[RunHost] = []  # the one host, once `serve` registered it


def serve(host: RunHost, broker_url: str, limits: TaskLimits) -> Celery:
    """Configure the app and hand its run task to `host` (before the worker starts)."""
    _hosts[:] = [host]
    return configure(broker_url, limits)


def _host() -> RunHost:
    if not _hosts:
        raise RuntimeError("no run host registered: start workers with `mapqual worker`")
    return _hosts[0]


@app.task(name=RUN_TASK, bind=True, acks_late=True, reject_on_worker_lost=True, max_retries=None)
def run_task(self: Task, run_id: int) -> str:
    """Execute one stored run exactly once. A delivery that finds another attempt alive comes
    back later (no retry cap), so that the run is finished even if that attempt dies; one
    that finds the run done, cancelled or failed does nothing."""
    host = _host()
    try:
        busy, message = host.execute(run_id)
    finally:
        release_free_heap()  # the run's freed maps, back to the system while the worker idles
    if busy:
        # well within the visibility timeout: Redis would redeliver a longer countdown's
        # message (held unacknowledged by the worker) before it is due
        raise self.retry(countdown=host.retry_after_s, max_retries=None)
    return message


@worker_process_init.connect
def _start_process(**_: Any) -> None:
    """Each worker process starts what its host keeps running (the sweeper for runs whose
    message a restarted broker lost)."""
    if _hosts:
        _hosts[0].start_process()
