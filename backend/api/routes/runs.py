"""Runs: summary and metrics, trajectories, the final map, relations, the whole report."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from fastapi import APIRouter, Query
from fastapi.responses import JSONResponse, PlainTextResponse, Response

from backend.api.artifacts import built, maybe_files, serve
from backend.api.deps import CurrentUser, IdPath, SessionDep, SettingsDep
from backend.core.schemas import RunOut
from backend.services import runs
from worker.report.summary import summary_json_schema

router = APIRouter(tags=["runs"])


@router.get("/schemas/summary")
def get_summary_schema() -> dict[str, Any]:
    """The JSON Schema of a run's summary (summary.json; `summary` in a run). Public, like
    the OpenAPI document that holds it too: it describes the API, no one's data."""
    return summary_json_schema()


@router.get("/runs/{run_id}", response_model=RunOut)
def get_run(run_id: IdPath, session: SessionDep, user: CurrentUser) -> RunOut:
    """A run: status, progress, and once done its summary and metrics."""
    return RunOut.of(runs.run_of(session, user, run_id))


@router.get("/runs/{run_id}/trajectory")
def get_trajectory(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    kind: Literal["gt", "est"] = Query("est", description="ground truth or estimate"),
    format: Literal["tum", "carmen", "json"] = Query("tum"),
) -> Response:
    """A trajectory at 10 Hz: TUM (evo reads it), CARMEN FLASER (the thesis), or JSON."""
    run = runs.done_run(session, user, run_id)
    t, poses = runs.trajectory(session, run, kind)
    if format == "json":
        return JSONResponse({"kind": kind, "t": t.tolist(), "poses": poses.tolist()})
    text = runs.trajectory_text(t, poses, format)
    name = f"run{run.id}_{kind}.{'tum' if format == 'tum' else 'log'}"
    return PlainTextResponse(text, headers={"Content-Disposition": f'inline; filename="{name}"'})


@router.get("/runs/{run_id}/map.{ext}")
def get_map(
    run_id: IdPath, ext: Literal["png", "pgm", "yaml"], session: SessionDep, user: CurrentUser
) -> Response:
    """The final SLAM map as map_server files (PGM + YAML) or PNG (with its errors written
    on it when the report folder is there)."""
    run = runs.done_run(session, user, run_id)
    files = maybe_files(run)
    if files is not None and files.has(f"map.{ext}"):
        return serve(files, f"map.{ext}", _MEDIA[ext], run.id, inline=True)
    return Response(runs.map_files(session, run)[ext], media_type=_MEDIA[ext])


_MEDIA = {"png": "image/png", "pgm": "image/x-portable-graymap", "yaml": "application/yaml"}


@router.get("/runs/{run_id}/relations")
def get_relations(
    run_id: IdPath,
    session: SessionDep,
    user: CurrentUser,
    kind: Literal["A", "B", "SM"] = Query("B"),
) -> Response:
    """The run's relations file of that kind (`t1 t2 x y z roll pitch yaw`)."""
    files, name = runs.relations_file(runs.run_of(session, user, run_id), kind)
    return serve(files, name, "text/plain; charset=utf-8", run_id, name)


@router.get("/runs/{run_id}/report.zip")
def get_report(
    run_id: IdPath, session: SessionDep, user: CurrentUser, settings: SettingsDep
) -> Response:
    """The whole report folder as one zip, streamed: the one written with the run's result,
    or (a run stored before runs had one, or a folder of `mapqual run -o` or a batch) made
    once now and kept beside the report."""
    from worker.report.folder import REPORT_ZIP, write_report_zip

    files = runs.report_files(runs.run_of(session, user, run_id))

    def build(work: Path) -> Path:
        folder = files.local_path("") or files.fetch(files.names(), work / "report")
        return write_report_zip(folder, f"run{run_id}", work / REPORT_ZIP)

    media, name = "application/zip", f"run{run_id}.zip"
    return built(files, REPORT_ZIP, settings.database_url, build, media, run_id, name)
