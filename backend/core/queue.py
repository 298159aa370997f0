"""Enqueueing runs: the API sends Celery tasks by name, so it never imports the pipeline.

Each run sent is stamped with the broker's epoch: a random id kept in a Redis key beside the
queue, made when missing. A broker that lost its queue (Redis restarted without persistence)
lost that key too, and the workers' sweeper (`backend.services.sweeper`) sends again the runs
stamped with an older epoch.
"""

from __future__ import annotations

import secrets
import time
from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

from celery import Celery
from sqlalchemy import update
from sqlalchemy.orm import Session

from backend.db.models import Run
from worker.celery_conf import RUN_TASK, producer_conf

if TYPE_CHECKING:
    from redis import Redis

EPOCH_KEY = "mapqual:broker_epoch"


@lru_cache(maxsize=4)
def _client(broker_url: str) -> Celery:
    """A producer-only app: the worker's wire format and queue (`worker.celery_conf`)."""
    app = Celery("mapqual-api")
    app.conf.update(producer_conf(broker_url))
    return app


@lru_cache(maxsize=4)
def _redis(broker_url: str) -> Redis:
    import redis

    return redis.Redis.from_url(broker_url, socket_connect_timeout=2, socket_timeout=5)


# How old [s] an epoch the API read may be when it stamps runs with it. A stale one costs at
# most an extra delivery: runs stamped with the epoch of a broker that restarted meanwhile are
# sent again by the sweeper, and the second delivery finds them running or done. Reading it
# for every job was an eighth of a POST /jobs.
EPOCH_MAX_AGE_S = 1.0
_seen: dict[str, tuple[str, float]] = {}  # broker URL -> (epoch, monotonic time read)


def broker_epoch(broker_url: str, max_age_s: float = 0.0) -> str:
    """The broker's current epoch, made (SET NX: one winner among racing processes) when the
    key is missing; raises on a broker that cannot be reached. With `max_age_s`, an epoch read
    that long ago or less is answered without asking."""
    seen = _seen.get(broker_url)
    if seen is not None and time.monotonic() - seen[1] <= max_age_s:
        return seen[0]
    client = _redis(broker_url)
    epoch = client.get(EPOCH_KEY)
    if epoch is None:
        client.set(EPOCH_KEY, secrets.token_hex(16), nx=True)
        epoch = client.get(EPOCH_KEY)
    _seen[broker_url] = (epoch.decode("ascii"), time.monotonic())
    return _seen[broker_url][0]


def enqueue_run(broker_url: str, run_id: int) -> None:
    """Queue one run; raises on a broker that cannot be reached."""
    _client(broker_url).send_task(RUN_TASK, args=[run_id], retry=False)


def send_runs(broker_url: str, run_ids: Sequence[int]) -> None:
    """Queue runs already stamped with the broker's epoch and committed (`create_job(...,
    broker_epoch=broker_epoch(url))`): no statement of its own. Raises on an unreachable
    broker."""
    for run_id in run_ids:
        enqueue_run(broker_url, run_id)


def enqueue_runs(session: Session, broker_url: str, run_ids: Sequence[int]) -> None:
    """Stamp the runs with the broker's epoch, commit, and queue them (committed first: a
    worker may pick a run up at once). Raises on a broker that cannot be reached."""
    if not run_ids:
        return
    epoch = broker_epoch(broker_url)
    session.execute(
        update(Run)
        .where(Run.id.in_([int(i) for i in run_ids]))
        .values(broker_epoch=epoch)
        .execution_options(synchronize_session=False)
    )
    session.commit()
    for run_id in run_ids:
        enqueue_run(broker_url, run_id)
