"""A run's sensor data as a ROS bag (GET /runs/{id}/bag) and external estimates scored on the
run's own relations (POST / GET /runs/{id}/estimates)."""

from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import APIRouter, File, Form, Query, Request, UploadFile
from fastapi.responses import Response

from backend.api.artifacts import built
from backend.api.deps import CurrentUser, IdPath, SessionDep, SettingsDep
from backend.services import estimates

router = APIRouter(tags=["runs"])


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
    files, log_name = estimates.sim_log(session, user, run_id)
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
    settings = request.app.state.settings
    upload = (file.filename, file.file.read())  # the body limit (BodyLimit) bounds it
    row = estimates.score_upload(session, user, settings, run_id, upload, name, topic)
    return _estimate_out(row)


@router.get("/runs/{run_id}/estimates")
def get_estimates(run_id: IdPath, session: SessionDep, user: CurrentUser) -> list[dict[str, Any]]:
    """The external estimates scored on the run, by name."""
    return [_estimate_out(r) for r in estimates.estimates_of(session, user, run_id)]
