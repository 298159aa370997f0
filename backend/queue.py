"""Enqueueing runs: the API sends Celery tasks by name, so it never imports the pipeline."""

from __future__ import annotations

from functools import lru_cache

from celery import Celery

RUN_TASK = "mapqual.run"


@lru_cache(maxsize=4)
def _client(broker_url: str) -> Celery:
    # A producer-only app with the worker's serialiser and queue (worker.celery_app has the rest).
    app = Celery("mapqual-api", broker=broker_url)
    app.conf.update(
        task_serializer="json",
        accept_content=["json"],
        task_default_queue="mapqual",
        broker_connection_retry=False,
        broker_connection_max_retries=0,
        broker_transport_options={"socket_connect_timeout": 2, "socket_timeout": 5},
    )
    return app


def enqueue_run(broker_url: str, run_id: int) -> None:
    """Queue one run; raises on a broker that cannot be reached."""
    _client(broker_url).send_task(RUN_TASK, args=[run_id], retry=False)
