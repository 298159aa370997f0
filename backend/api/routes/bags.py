"""A run's sensor data as a ROS bag (GET /runs/{id}/bag) and external estimates scored on the
run's own relations (POST / GET /runs/{id}/estimates)."""

from __future__ import annotations

import os
import re
import shutil
import tempfile
import zipfile
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import APIRouter, File, Form, HTTPException, Query, Request, UploadFile, status
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask

from backend import quotas
from backend.api.deps import CurrentUser, IdPath, SessionDep
from backend.api.routes.runs import _report_dir, _run
from backend.sandbox import Sandbox, sandbox
from backend.store_estimates import list_estimates, save_estimate
from worker.errors import InputError

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
    format: Literal["rosbag2", "rosbag1"] = Query("rosbag2", description="bag format"),
) -> FileResponse:
    """The run's sim.log as a bag: rosbag1 (one .bag) or rosbag2 (MCAP; its directory as a
    zip). Built once into the run's folder (`export/`), then served from there until the log
    changes (a 2 h run's bag takes a minute to build); where that folder cannot be written,
    built in a temporary folder for this response and deleted afterwards."""
    from worker.export.bag import find_sim_log

    folder = _report_dir(_run(session, user, run_id))
    try:
        log = find_sim_log(folder)
    except InputError:
        raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run_id} has no sim.log") from None
    name = f"run{run_id}"
    file_name = f"{name}.bag" if format == "rosbag1" else f"{name}_rosbag2.zip"
    media = "application/octet-stream" if format == "rosbag1" else "application/zip"
    cached = folder / "export" / file_name
    if cached.is_file() and cached.stat().st_mtime_ns >= log.stat().st_mtime_ns:
        return FileResponse(cached, media_type=media, filename=file_name)
    try:
        cached.parent.mkdir(exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix=".building-", dir=cached.parent))
    except OSError:  # a read-only report folder
        work = Path(tempfile.mkdtemp(prefix="mapqual-bag-"))
        built = _build_bag(log, work, name, format)
        cleanup = BackgroundTask(shutil.rmtree, work, ignore_errors=True)
        return FileResponse(built, media_type=media, filename=file_name, background=cleanup)
    try:
        # built aside, then renamed into place: a request served meanwhile gets a whole file
        os.replace(_build_bag(log, work, name, format), cached)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return FileResponse(cached, media_type=media, filename=file_name)


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
    from worker.export.score import check_name, score_estimate

    check_name(name)
    upload_name = Path(file.filename or "").name
    if not _FILE_NAME.match(upload_name):
        raise HTTPException(status.HTTP_400_BAD_REQUEST, f"unsafe file name {file.filename!r}")
    run = _run(session, user, run_id)
    folder = _report_dir(run)
    data = file.file.read()  # the body limit (BodyLimit) bounds it
    settings = request.app.state.settings
    quotas.check_estimates(session, user.id, settings, run.id, name)
    # parsed in a limited process of its own: a typed, validated trajectory or a 400
    est = read_estimate_sandboxed(sandbox(request.app), upload_name, data, topic)
    stored_bytes = 4 * 8 * len(est.t)  # (t, x, y, yaw) float64 a pose, before packing
    quotas.check_estimates(session, user.id, settings, run.id, name, new_bytes=stored_bytes)
    try:
        score = score_estimate(folder, est, name, upload_name)
    except InputError as exc:
        if "cannot create directory" in str(exc):
            unavailable = status.HTTP_503_SERVICE_UNAVAILABLE
            raise HTTPException(unavailable, f"run {run_id}: {exc}") from None
        raise
    row = save_estimate(session, run, summary=score.summary, t=est.t, poses=est.poses,
                        report_dir=str(score.folder))  # fmt: skip
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


@router.get("/runs/{run_id}/estimates")
def get_estimates(run_id: IdPath, session: SessionDep, user: CurrentUser) -> list[dict[str, Any]]:
    """The external estimates scored on the run, by name."""
    run = _run(session, user, run_id)
    return [_estimate_out(r) for r in list_estimates(session, [run.id])]
