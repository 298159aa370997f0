"""One delivery of a queued run, executed exactly once: claim it under a new attempt, run the
pipeline into the attempt's own folder, and keep the result (or the failure) only while the
attempt still holds the run; an attempt that lost keeps nothing and deletes its folder."""

from __future__ import annotations

import logging
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from backend.core.config import Settings
from backend.db.models import Run, World
from backend.db.session import session_scope
from backend.lifecycle import (
    TransitionRefused,
    attempt_dir,
    claim_run,
    new_attempt,
    remove_attempt_dirs,
)
from backend.progress import ProgressReporter
from backend.store import mark_run_failed, store_run_result, world_model

log = logging.getLogger("mapqual.execute")
Kind = Literal["busy", "skipped", "done", "lost", "cancelled", "failed"]


@dataclass(frozen=True)
class Outcome:
    """What became of a delivery: `busy` means another attempt is alive and the delivery
    should come back later; every other kind is final for this delivery."""

    kind: Kind
    message: str


def execute_run(run_id: int, settings: Settings, redis_client: Any | None = None) -> Outcome:
    """Claim, run, and store run `run_id` (see the module's docstring)."""
    from worker.pipeline import RunCancelled, RunParams, RunSuperseded

    url, attempt = settings.database_url, new_attempt()
    with session_scope(url) as s:
        answer, run = claim_run(s, run_id, attempt, settings.run_lease_s)
        if run is None:
            kind: Kind = "busy" if answer == "busy" else "skipped"
            return Outcome(kind, f"run {run_id}: not run ({answer})")
        world = world_model(s.get_one(World, run.world_id))
        params, seed = RunParams.from_json(run.params), run.seed
    final = (settings.runs_dir / str(run_id)).resolve()
    folder = attempt_dir(final, attempt)
    reporter = ProgressReporter(url, run_id, redis_client, attempt=attempt)
    try:
        result = run_and_store(url, run_id, attempt, (world, params, seed), reporter, folder, final)
    except RunSuperseded as exc:
        return _lost(folder, "lost", f"run {run_id}: {exc}")
    except RunCancelled:
        return _lost(folder, "cancelled", f"run {run_id}: cancelled")
    except TransitionRefused as exc:
        return _lost(folder, "lost", f"run {run_id}: result not stored ({exc})")
    except Exception as exc:  # SoftTimeLimitExceeded included: the run failed, not the worker
        log.exception("run %s failed", run_id)
        return _failed(url, run_id, attempt, folder, final, f"{type(exc).__name__}: {exc}")
    remove_attempt_dirs(final)  # whatever attempts that lost earlier (killed ones) left
    return Outcome("done", f"run {run_id}: {result.summary.outcome}")


def run_and_store(
    url: str,
    run_id: int,
    attempt: str,
    job: tuple[Any, Any, int],
    on_progress: Any,
    folder: Path,
    final: Path,
    rename: bool = True,
) -> Any:
    """Run the pipeline on `job` = (world, RunParams, seed) writing into `folder`, write the
    report there, and store the result as `attempt`'s in one transaction, `folder` renamed to
    `final` inside it (`rename=False`: the report stays where it was written, as `final`).
    The `RunResult`; TransitionRefused when the attempt no longer holds the run."""
    from worker.pipeline import run_one
    from worker.report.folder import SIM_LOG, write_report

    world, params, seed = job
    result = run_one(world, params, seed, on_progress, sim_log=folder / SIM_LOG)
    write_report(result, folder)
    ex = result.exploration
    with session_scope(url) as s:
        store_run_result(
            s, run_id, summary=result.summary, t=ex.t, pose_gt=ex.pose_gt,
            pose_est=ex.pose_est, map_ros=ex.final_map.to_ros(),
            map_resolution=ex.final_map.resolution, map_origin=ex.final_map.origin,
            report_dir=str(final), attempt=attempt, folder=folder if rename else None,
        )  # fmt: skip
    return result


def _lost(folder: Path, kind: Kind, message: str) -> Outcome:
    """This attempt no longer holds the run: it keeps nothing."""
    shutil.rmtree(folder, ignore_errors=True)
    log.info("%s", message)
    return Outcome(kind, message)


def _failed(url: str, run_id: int, attempt: str, folder: Path, final: Path, error: str) -> Outcome:
    """Mark the run failed if this attempt still holds it (a cancelled run stays cancelled)."""
    shutil.rmtree(folder, ignore_errors=True)
    with session_scope(url) as s:
        if not mark_run_failed(s, run_id, error, attempt):
            return Outcome("lost", f"run {run_id}: failed, but no longer this attempt's ({error})")
        # a run folder there now is the leftover of an interrupted rename-and-commit
        if s.get_one(Run, run_id).status != "done":
            shutil.rmtree(final, ignore_errors=True)
    return Outcome("failed", f"run {run_id}: failed ({error})")
