"""Celery tasks: thin shells that load a run, call `pipeline.run_one`, and persist."""

from __future__ import annotations

import logging
import shutil

from celery.exceptions import SoftTimeLimitExceeded

from worker.celery_app import app

log = logging.getLogger("mapqual.tasks")


@app.task(name="mapqual.run", acks_late=True, reject_on_worker_lost=True)
def run_task(run_id: int) -> str:
    """Execute one stored run; idempotent: a run already done is not done again, and a run
    interrupted mid-way (a worker killed, the task redelivered) starts over from scratch."""
    from backend.core.config import get_settings
    from backend.db.models import Run, World
    from backend.db.session import session_scope
    from backend.progress import ProgressReporter
    from backend.store import mark_run_failed, mark_run_started, store_run_result, world_model
    from worker.pipeline import RunCancelled, RunParams, run_one
    from worker.report.folder import SIM_LOG, write_report

    settings = get_settings()
    url = settings.database_url
    with session_scope(url) as s:
        run = s.get(Run, run_id)
        if run is None or run.status in ("done", "cancelled"):
            return f"run {run_id}: nothing to do ({'missing' if run is None else run.status})"
        mark_run_started(s, run_id)
        world = world_model(s.get_one(World, run.world_id))
        params, seed = RunParams.from_json(run.params), run.seed
    out_dir = (settings.runs_dir / str(run_id)).resolve()
    shutil.rmtree(out_dir, ignore_errors=True)  # leftovers of an interrupted attempt
    reporter = ProgressReporter(url, run_id, _redis(settings.redis_url))
    try:
        result = run_one(world, params, seed, reporter, sim_log=out_dir / SIM_LOG)
        write_report(result, out_dir)
        ex = result.exploration
        with session_scope(url) as s:
            if s.get_one(Run, run_id).status == "cancelled":
                return f"run {run_id}: cancelled"
            store_run_result(
                s, run_id, summary=result.summary, t=ex.t, pose_gt=ex.pose_gt,
                pose_est=ex.pose_est, map_ros=ex.final_map.to_ros(),
                map_resolution=ex.final_map.resolution, map_origin=ex.final_map.origin,
                report_dir=str(out_dir),
            )  # fmt: skip
    except RunCancelled:
        return f"run {run_id}: cancelled"
    except SoftTimeLimitExceeded:
        with session_scope(url) as s:
            mark_run_failed(s, run_id, "the task's time limit was exceeded")
        return f"run {run_id}: time limit"
    except Exception as exc:
        log.exception("run %s failed", run_id)
        with session_scope(url) as s:
            mark_run_failed(s, run_id, f"{type(exc).__name__}: {exc}")
        return f"run {run_id}: failed"
    return f"run {run_id}: {result.summary['outcome']}"


def _redis(url: str):
    import redis

    try:
        client = redis.Redis.from_url(url, socket_connect_timeout=1, socket_timeout=1)
        client.ping()
        return client
    except Exception:
        log.warning("no Redis at %s: live progress is not published", url)
        return None
