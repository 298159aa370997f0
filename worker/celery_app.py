"""The one Celery app (tasks in `worker.tasks`; configured by `worker.tasks.serve`)."""

from __future__ import annotations

from celery import Celery

from worker.celery_conf import TaskLimits, worker_conf

app = Celery("mapqual", include=["worker.tasks"])


def configure(broker_url: str, limits: TaskLimits) -> Celery:
    """Give the app its whole configuration (`worker.celery_conf.worker_conf`)."""
    app.conf.update(worker_conf(broker_url, limits))
    return app
