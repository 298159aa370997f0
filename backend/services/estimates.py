"""External estimates scored on a run's own relations: an upload parsed in the sandbox,
checked against the owner's quotas, scored, written beside the run's report and stored as
another algorithm of the run (POST / GET /runs/{id}/estimates); and the sim.log a run's bag is
made from (GET /runs/{id}/bag)."""

from __future__ import annotations

import re
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from sqlalchemy.orm import Session

from backend.core.config import Settings
from backend.db.models import RunEstimate
from backend.sandbox.manager import Sandbox, shared_sandbox
from backend.services import quotas
from backend.services.access import Principal
from backend.services.errors import Invalid, NotFound
from backend.services.runs import report_files, run_of, unreachable
from backend.store.estimates import list_estimates, save_estimate
from worker.errors import InputError
from worker.storage import RunFiles, StorageError

FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,120}$")
POSE_BYTES = 4 * 8  # (t, x, y, yaw) float64 a pose, before packing


def sim_log(session: Session, user: Principal, run_id: int) -> tuple[RunFiles, str]:
    """(the run's report folder, the name of its sim.log as stored): NotFound without one."""
    from worker.export.bag import SIM_LOG_NAMES

    files = report_files(run_of(session, user, run_id))
    log_name = next((n for n in SIM_LOG_NAMES if files.has(n)), None)
    if log_name is None:
        raise NotFound(f"run {run_id} has no sim.log")
    return files, log_name


def score_upload(
    session: Session,
    user: Principal,
    settings: Settings,
    run_id: int,
    upload: tuple[str | None, bytes],
    name: str,
    topic: str | None,
) -> RunEstimate:
    """Score the uploaded estimate (`upload`: its file name as sent, its bytes) on the run's
    B, A and SM relations and store it as algorithm `name` of the run (a name again replaces
    the earlier one), parsed by the settings' sandbox. Invalid for an unsafe file name,
    InputError for an estimate that does not cover the run, QuotaExceeded past the owner's
    estimate quotas."""
    from worker.export.score import check_name

    check_name(name)
    filename, data = upload
    upload_name = Path(filename or "").name
    if not FILE_NAME.match(upload_name):
        raise Invalid(f"unsafe file name {filename!r}")
    run = run_of(session, user, run_id)
    files = report_files(run)
    quotas.check_estimates(session, user.id, settings, run.id, name)
    # parsed in a limited process of its own: a typed, validated trajectory or a 400
    est = read_estimate_sandboxed(shared_sandbox(settings), upload_name, data, topic)
    new_bytes = POSE_BYTES * len(est.t)
    quotas.check_estimates(session, user.id, settings, run.id, name, new_bytes=new_bytes)
    summary, location = _score_into_storage(files, est, name, upload_name, run_id)
    return save_estimate(session, run, summary=summary, t=est.t, poses=est.poses,
                         report_dir=location)  # fmt: skip


def read_estimate_sandboxed(box: Sandbox, upload_name: str, data: bytes, topic: str | None):
    """The uploaded estimate as a Trajectory, parsed in the sandbox and checked again here."""
    from worker.evaluate.trajectory import Trajectory

    parsed = box.run("estimate", {upload_name: data}, file=upload_name, topic=topic)
    samples = parsed.samples
    if samples is None or len(samples) == 0:
        raise InputError(f"{upload_name}: no poses")
    if not np.isfinite(samples).all():
        raise InputError(f"{upload_name}: the estimate holds values that are not finite")
    try:
        return Trajectory(samples[:, 0].copy(), samples[:, 1:4].copy())
    except ValueError as exc:
        raise InputError(f"{upload_name}: {exc}") from None


def _score_into_storage(
    files: RunFiles, est: Any, name: str, upload_name: str, run_id: int
) -> tuple[dict[str, Any], str]:
    """Score `est` on the run's parts fetched from its storage, write the estimate's report
    folder back there as `estimates/<name>/`: (its summary, that folder's location)."""
    # here, not at the top: the scorer pulls numba, which the API process loads only once
    # it scores an estimate (uploads, worlds and predictions never load it)
    from worker.export.score import ESTIMATES_DIR, RUN_PARTS, score_estimate

    with tempfile.TemporaryDirectory(prefix="mapqual-score-") as tmp:
        run_dir = files.local_path("") or files.fetch(RUN_PARTS, Path(tmp) / "run")
        out = Path(tmp) / "estimate"
        score = score_estimate(run_dir, est, name, upload_name, out_dir=out)
        target = files.sub(f"{ESTIMATES_DIR}/{name}")
        try:
            target.put_tree("", out)  # the same file names: a name again replaces its files
        except (StorageError, OSError) as exc:
            raise unreachable(run_id, exc) from None
        return score.summary, target.location


def estimates_of_runs(session: Session, run_ids: list[int]) -> list[RunEstimate]:
    """The external estimates of these runs (the caller was allowed to read them), by run then
    name."""
    return list_estimates(session, run_ids)


def estimates_of(session: Session, user: Principal, run_id: int) -> list[RunEstimate]:
    """The external estimates scored on the run, by name."""
    run = run_of(session, user, run_id)
    return list_estimates(session, [run.id])
