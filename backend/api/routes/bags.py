"""A run's sensor data as a ROS bag (GET /runs/{id}/bag) and external estimates scored on the
run's own relations (POST / GET /runs/{id}/estimates)."""

from __future__ import annotations

import re
import tempfile
import zipfile
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Query, Request, UploadFile, status
from fastapi.responses import Response

from backend.api.artifacts import built, report_files, unavailable
from backend.api.deps import CurrentUser, IdPath, SessionDep, SettingsDep
from backend.sandbox.manager import Sandbox, sandbox
from backend.services import quotas
from backend.services.runs import run_of
from backend.store.estimates import list_estimates, save_estimate
from worker.errors import InputError
from worker.storage import RunFiles, StorageError

router = APIRouter(tags=["runs"])

_FILE_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,120}$")


def _estimate_out(row) -> dict[str, Any]:
    return {
        "id": row.id, "run_id": row.run_id, "name": row.name, "source": row.source,
        "n_poses": row.n_poses, "b_mean_t": row.b_mean_t, "b_mean_r": row.b_mean_r,
        "metrics": row.metrics, "created_at": row.created_at.isoformat(),
    }  # fmt: skip


@router.get("/runs/{run_id}/bag")
def get_bag(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    settings: SettingsDep,
    format: Literal["rosbag2", "rosbag1"] = Query("rosbag2", description="bag format"),
) -> Response:
    """The run's sim.log as a bag: rosbag1 (one .bag) or rosbag2 (MCAP; its directory as a
    zip). Built once (a 2 h run's bag takes a minute), by one request at a time per run and
    format (the others wait for it), kept in the run's storage as `export/<file>` and
    streamed from there; where the run's folder cannot be written, built for this response."""
    from worker.export.bag import SIM_LOG_NAMES

    files = report_files(run_of(session, user, run_id))
    log_name = next((n for n in SIM_LOG_NAMES if files.has(n)), None)
    if log_name is None:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run_id} has no sim.log")
    name = f"run{run_id}"
    file_name = f"{name}.bag" if format == "rosbag1" else f"{name}_rosbag2.zip"
    media = "application/octet-stream" if format == "rosbag1" else "application/zip"

    def build(work: Path) -> Path:
        log = files.local_path(log_name) or files.fetch([log_name], work / "log") / log_name
        return _build_bag(log, work, name, format)

    key, url = f"export/{file_name}", settings.database_url
    return built(files, key, url, build, media, run_id, file_name, source=log_name)


def _build_bag(log: Path, work: Path, name: str, format: str) -> Path:
    """The bag of `log` in the folder `work`: `name`.bag, or `name`_rosbag2.zip holding the
    rosbag2 directory `name`/."""
    from worker.export.bag import export_bag

    if format == "rosbag1":
        return export_bag(log, work / f"{name}.bag", "rosbag1").path
    bag = export_bag(log, work / name, "rosbag2").path
    path = work / f"{name}_rosbag2.zip"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_STORED) as zf:
        for f in sorted(bag.iterdir()):
            zf.write(f, f"{name}/{f.name}")
    return path


@router.post("/runs/{run_id}/estimates", status_code=201)
def post_estimate(
    run_id: IdPath,
    request: Request,
    session: SessionDep,
    user: CurrentUser,
    file: Annotated[UploadFile, File(description="TUM, CARMEN, .bag, .mcap, .db3, rosbag2 .zip")],
    name: Annotated[str, Form(description="the algorithm's name")] = "external",
    topic: Annotated[str | None, Form(max_length=200, description="bag: pose topic")] = None,
) -> dict[str, Any]:
    """Score an estimate of the run's motion on the run's own B, A and SM relations and store
    it as an algorithm of the run (a name again replaces the earlier one). 400 with one line
    for an estimate that does not cover the run, is in another frame, or mixes units; 429
    past the owner's estimate quotas."""
    from worker.export.score import check_name

    check_name(name)
    upload_name = Path(file.filename or "").name
    if not _FILE_NAME.match(upload_name):
        raise HTTPException(status.HTTP_400_BAD_REQUEST, f"unsafe file name {file.filename!r}")
    run = run_of(session, user, run_id)
    files = report_files(run)
    data = file.file.read()  # the body limit (BodyLimit) bounds it
    settings = request.app.state.settings
    quotas.check_estimates(session, user.id, settings, run.id, name)
    # parsed in a limited process of its own: a typed, validated trajectory or a 400
    est = read_estimate_sandboxed(sandbox(request.app), upload_name, data, topic)
    stored_bytes = 4 * 8 * len(est.t)  # (t, x, y, yaw) float64 a pose, before packing
    quotas.check_estimates(session, user.id, settings, run.id, name, new_bytes=stored_bytes)
    summary, location = _score_into_storage(files, est, name, upload_name, run_id)
    row = save_estimate(session, run, summary=summary, t=est.t, poses=est.poses,
                        report_dir=location)  # fmt: skip
    return _estimate_out(row)


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
            raise unavailable(run_id, exc) from None
        return score.summary, target.location


@router.get("/runs/{run_id}/estimates")
def get_estimates(run_id: IdPath, session: SessionDep, user: CurrentUser) -> list[dict[str, Any]]:
    """The external estimates scored on the run, by name."""
    run = run_of(session, user, run_id)
    return [_estimate_out(r) for r in list_estimates(session, [run.id])]
