"""The workers' sweeper: runs whose message a broker lost (Redis restarted without
persistence) are sent again, and nothing is sent again while the broker keeps its queue.

A run sent to the queue carries the broker's epoch (`backend.core.queue.enqueue_runs`). Every few
seconds each worker reads the current epoch; a run still queued, or running with no sign of
life for the lease, that carries another epoch had its message in a queue that no longer
exists. Each such run is re-stamped by a conditional update (so that of two sweepers, one
sends it) and sent again. Runs never sent through a broker (the CLI's) carry no epoch and are
left alone.
"""

from __future__ import annotations

import logging
import threading
import time
from datetime import timedelta

from sqlalchemy import and_, or_, select, update

from backend.core.queue import broker_epoch, enqueue_run
from backend.db.models import Run, utcnow
from backend.db.session import session_scope
from worker.status import RunStatus

log = logging.getLogger("mapqual.sweeper")
SWEEP_EVERY_S = 3.0  # [s]


def sweep(database_url: str, broker_url: str, lease_s: float) -> list[int]:
    """One sweep: the ids of the runs this sweeper sent again."""
    epoch = broker_epoch(broker_url)
    cutoff = utcnow() - timedelta(seconds=lease_s)
    lost = and_(
        Run.broker_epoch.is_not(None),
        Run.broker_epoch != epoch,
        or_(
            Run.status == RunStatus.QUEUED,
            and_(
                Run.status == RunStatus.RUNNING,
                or_(Run.heartbeat_at.is_(None), Run.heartbeat_at <= cutoff),
            ),
        ),
    )
    sent: list[int] = []
    with session_scope(database_url) as s:
        candidates = s.execute(select(Run.id, Run.broker_epoch).where(lost)).all()
    for run_id, old in candidates:
        with session_scope(database_url) as s:
            stmt = (
                update(Run)
                .where(Run.id == run_id, Run.broker_epoch == old, lost)
                .values(broker_epoch=epoch)
                .execution_options(synchronize_session=False)
            )
            if s.execute(stmt).rowcount != 1:
                continue  # another sweeper took it, or it finished meanwhile
        # sent after the commit; a send that fails puts the old epoch back, so that the next
        # sweep tries again instead of taking the run for one sent in this epoch
        try:
            enqueue_run(broker_url, run_id)
        except Exception:
            with session_scope(database_url) as s:
                s.execute(
                    update(Run)
                    .where(Run.id == run_id, Run.broker_epoch == epoch)
                    .values(broker_epoch=old)
                    .execution_options(synchronize_session=False)
                )
            raise
        log.warning("run %s: its message was lost with the broker's queue; sent again", run_id)
        sent.append(run_id)
    return sent


def start_sweeper(
    database_url: str, broker_url: str, lease_s: float, every_s: float = SWEEP_EVERY_S
) -> threading.Thread:
    """Sweep every `every_s` in a daemon thread of this process, for as long as it lives."""

    def loop() -> None:
        while True:
            time.sleep(every_s)
            try:
                sweep(database_url, broker_url, lease_s)
            except Exception as exc:  # a broker or database away: the next sweep tries again
                log.info("sweep skipped: %s: %s", type(exc).__name__, exc)

    thread = threading.Thread(target=loop, name="mapqual-sweeper", daemon=True)
    thread.start()
    return thread
