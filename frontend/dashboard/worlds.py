"""The dashboard's worlds page: thumbnails with their facts, the upload form, and the bundled
data sets with a button that makes one of their worlds yours."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Path, Request, UploadFile
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from backend.api.deps import SessionDep, SettingsDep, prediction_cache, world_pool
from backend.api.errors import as_http
from backend.core.schemas import DatasetOut
from backend.db.models import World
from backend.services import worlds as worlds_service
from backend.services.datasets import bundled, import_bundled, imported_ids
from backend.services.errors import ServiceError
from frontend.dashboard.pages import PageUser, render, user_worlds
from worker.errors import InputError
from worker.status import WorldStatus

router = APIRouter(include_in_schema=False)

# the world facts as the worlds page labels them: (label, unit after the value; " %": a
# fraction shown in per cent)
FACT_LABELS = {
    "free_area_m2": ("free area", " m²"),
    "free_fraction": ("free share of the plan", " %"),
    "n_free_regions": ("free regions", ""),
    "largest_region_area_m2": ("largest region", " m²"),
    "largest_region_share": ("its share of the free area", " %"),
    "main_region_enclosed": ("largest region enclosed", ""),
    "border_free": ("free space at the border", ""),
    "clearance_mean_m": ("clearance, mean", " m"),
    "clearance_median_m": ("clearance, median", " m"),
    "clearance_p90_m": ("clearance, 90th percentile", " m"),
    "clearance_max_m": ("clearance, max", " m"),
    "n_rooms": ("rooms", ""),
}


def _predictions(request, session, worlds) -> dict[int, dict]:
    """Per ready world: the bundled model's rbpf prediction and measured errors, or
    {"error": why} (a plan with no enclosed free space, say)."""
    out: dict[int, dict] = {}
    for w in worlds:
        if w.status != WorldStatus.READY:
            continue
        try:
            row = session.get(World, w.id)
            cache = prediction_cache(request.app)
            out[w.id] = worlds_service.world_prediction_of(cache, session, row, "rbpf")
        except InputError as exc:
            out[w.id] = {"error": str(exc)}
    return out


def _worlds_page(request, session, user, error=None, notice=None, status_code=200):
    from worker.world.features import FEATURE_DOCS

    worlds = user_worlds(session, user)
    # reload until every analysis is done; not an error page, which answers a POST (a reload
    # would send the form again)
    refresh = error is None and any(w.status == WorldStatus.PENDING for w in worlds)
    return render(
        request, "worlds.html", status_code, user=user, worlds=worlds,
        error=error, notice=notice, fact_labels=FACT_LABELS, refresh=refresh,
        predictions=_predictions(request, session, worlds), feature_docs=FEATURE_DOCS,
        **_bundled(session, user),
    )  # fmt: skip


def _bundled(session, user) -> dict:
    """The bundled data sets as the API lists them (the process's catalogue, loaded once; no
    predictions: 63 of them would slow every visit), and which of their worlds the user has
    already, as (data set, world) -> world id."""
    sets = bundled().datasets()
    mine = imported_ids(session, user)
    have = {
        (d.name, w.name): mine[w.fingerprint]
        for d in sets
        for w in d.worlds
        if w.fingerprint in mine
    }
    return {"datasets": [DatasetOut.of(d) for d in sets], "imported": have}


_STATE = {
    WorldStatus.PENDING: "is being analysed",
    WorldStatus.READY: "is ready",
    WorldStatus.INVALID: "is invalid",
}


@router.get("/worlds", response_class=HTMLResponse)
def worlds_page(
    request: Request,
    session: SessionDep,
    user: PageUser,
    uploaded: int | None = None,
    again: bool = False,
    bundled: bool = False,
) -> HTMLResponse:
    """Worlds as thumbnails with their facts; an upload form; the bundled data sets. After an
    upload or an import (`uploaded`, `bundled`), a notice says where that world stands."""
    notice = None
    w = session.get(World, uploaded) if uploaded is not None else None
    if w is not None and (user.is_admin or w.owner_id == user.id):
        if bundled:
            verb = "is already yours" if again else "added to your worlds"
            notice = f"world {w.name!r} {verb} as #{w.id}; it {_STATE[w.status]} for jobs"
        else:
            verb = "already stored" if again else "stored"
            notice = f"world {w.name!r} {verb} as #{w.id}; it {_STATE[w.status]}"
    return _worlds_page(request, session, user, None, notice)


@router.post("/worlds", response_class=HTMLResponse)
def upload_world_form(
    request: Request,
    session: SessionDep,
    user: PageUser,
    settings: SettingsDep,
    file: Annotated[list[UploadFile], File()],
    resolution: Annotated[str, Form()] = "",
) -> Response:
    """Upload through the worlds service, as the API does; its answer (or its error) is shown
    on the page."""
    try:
        res = float(resolution) if resolution.strip() else None
    except ValueError:
        res = -1.0
    if res is not None and not res > 0:
        msg = f"the resolution must be a positive number of metres per pixel, not {resolution!r}"
        return _worlds_page(request, session, user, msg, None, 400)
    try:
        names = worlds_service.checked_names([f.filename for f in file])
        files = {name: f.file.read() for name, f in zip(names, file, strict=True)}
        row, fresh = worlds_service.accept_upload(session, user, settings, files, res)
    except ServiceError as exc:
        session.rollback()
        return _worlds_page(request, session, user, str(exc), None, as_http(exc).status_code)
    except InputError as exc:
        session.rollback()
        return _worlds_page(request, session, user, str(exc), None, 400)
    session.commit()  # the analysis runs in another process: it must see the row
    if fresh:
        world_pool(request.app).submit(row.id)
    # POST, redirect, GET: the page then reloads itself while the world is pending
    again = "" if fresh else "&again=1"
    return RedirectResponse(f"/worlds?uploaded={row.id}{again}", status_code=303)


@router.post("/worlds/bundled/{dataset}/{name:path}", response_class=HTMLResponse)
def import_bundled_form(
    request: Request,
    session: SessionDep,
    user: PageUser,
    settings: SettingsDep,
    dataset: Annotated[str, Path(max_length=100)],
    name: Annotated[str, Path(max_length=200)],
) -> Response:
    """Import a bundled world through the same service as the API; then back to the page."""
    try:
        row, fresh = import_bundled(session, user, settings, dataset, name)
    except ServiceError as exc:  # no such data set or world (404), over the quota (429)
        session.rollback()
        return _worlds_page(request, session, user, str(exc), None, as_http(exc).status_code)
    session.commit()
    again = "" if fresh else "&again=1"
    return RedirectResponse(f"/worlds?uploaded={row.id}&bundled=1{again}", status_code=303)
