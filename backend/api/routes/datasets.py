"""Bundled data sets (the folders under worlds/): list them with their worlds, get a world's
picture and the data set's licence, and import a world as one of your own, ready for jobs."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path, Query
from fastapi.responses import JSONResponse, PlainTextResponse, Response

from backend.api.deps import CurrentUser, SessionDep, SettingsDep
from backend.core.schemas import DatasetOut, WorldOut
from backend.services.datasets import bundled, import_bundled

router = APIRouter(tags=["datasets"])

# Names in a path are only ever looked up in the catalogue; the bound keeps messages short.
DatasetName = Annotated[str, Path(max_length=100, description="a data set's name")]
WorldName = Annotated[str, Path(max_length=200, description="a world's name in its data set")]


@router.get("/datasets", response_model=list[DatasetOut])
def list_datasets(user: CurrentUser) -> list[DatasetOut]:
    """The data sets bundled with mapqual, each with its licence and its worlds' facts."""
    return [DatasetOut.of(d) for d in bundled().datasets()]


@router.get("/datasets/{dataset}/licence", response_class=PlainTextResponse)
def dataset_licence(dataset: DatasetName, user: CurrentUser) -> PlainTextResponse:
    """The text of the data set's licence file (its source and terms)."""
    return PlainTextResponse(bundled().licence(dataset))


@router.get("/datasets/{dataset}/worlds/{name:path}/image", response_class=Response)
def dataset_world_image(
    dataset: DatasetName,
    name: WorldName,
    user: CurrentUser,
    max_px: Annotated[int | None, Query(ge=16, le=4096)] = None,
) -> Response:
    """The world's floorplan as the pipeline sees it: PNG, obstacles black, free white; with
    max_px, a thumbnail no side of which exceeds it (obstacles kept)."""
    png = bundled().thumbnail(dataset, name, max_px)
    return Response(png, media_type="image/png", headers={"Cache-Control": "private, max-age=300"})


_ANSWERS: dict[int | str, dict[str, Any]] = {
    200: {"model": WorldOut, "description": "You have this world already: that world."},
    201: {"model": WorldOut, "description": "Stored as a world of yours, ready."},
    404: {"description": "No such data set, or no such world in it."},
    429: {"description": "Over your world quota."},
}


@router.post(
    "/datasets/{dataset}/worlds/{name:path}/import",
    response_model=WorldOut,
    status_code=201,
    responses=_ANSWERS,
)
def import_dataset_world(
    dataset: DatasetName, name: WorldName, session: SessionDep, user: CurrentUser,
    settings: SettingsDep,
) -> JSONResponse:  # fmt: skip
    """Make the bundled world a world of yours (ready at once: the bundled worlds are
    analysed as they are loaded), to submit jobs on by its id."""
    row, fresh = import_bundled(session, user, settings, dataset, name)
    out = WorldOut.of(row)
    return JSONResponse(out.model_dump(mode="json"), status_code=201 if fresh else 200)
