"""The dashboard: server-rendered pages (Jinja2) over the same handlers and access rules as
the REST API; a browser signs in with its API key and then holds a session cookie."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Annotated, Any
from urllib.parse import quote, urlsplit

from fastapi import (
    APIRouter,
    Depends,
    FastAPI,
    File,
    Form,
    Header,
    HTTPException,
    Request,
    UploadFile,
)
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates
from pydantic import ValidationError
from sqlalchemy import select

from backend.api.deps import (
    CSRF_FIELD,
    CSRF_HEADER,
    SESSION_COOKIE,
    IdPath,
    Principal,
    SessionDep,
    SettingsDep,
    current_user,
    owned,
    require_csrf,
)
from backend.api.routes import jobs as jobs_api
from backend.api.routes import stats as stats_api
from backend.api.routes import worlds as worlds_api
from backend.db.models import Job, Run, World
from backend.schemas import JobIn, WorldOut
from backend.store import create_web_session, delete_web_session, user_for_key, web_session_user
from backend.world_analysis import world_pool
from worker.errors import InputError
from worker.report.summary import RunSummary

FRONTEND = Path(__file__).resolve().parents[3] / "frontend"
templates = Jinja2Templates(directory=FRONTEND / "templates")
router = APIRouter(include_in_schema=False)
ACTIVE = ("queued", "running")
# Where the API key lived in the cookie before sessions: no longer read, deleted on sign-in.
OLD_KEY_COOKIE = "mapqual_key"


class SignInRequired(Exception):
    """A page was asked for without a valid key: the browser is sent to the sign-in page."""

    def __init__(self, next_path: str):
        self.next_path = next_path


async def page_user(
    request: Request,
    settings: SettingsDep,
    authorization: Annotated[str | None, Header()] = None,
    x_api_key: Annotated[str | None, Header()] = None,
) -> Principal:
    """The signed-in user, exactly as the API decides it; without one, the sign-in page."""
    try:
        return await current_user(request, settings, authorization, x_api_key)
    except HTTPException as exc:
        if exc.status_code == 401:
            raise SignInRequired(request.url.path) from None
        raise


PageUser = Annotated[Principal, Depends(page_user)]


def install(app: FastAPI) -> None:
    """Add the pages, their static files and the sign-in redirect to `app`."""
    app.include_router(router)
    app.mount("/static", StaticFiles(directory=FRONTEND / "static"), name="static")

    @app.exception_handler(SignInRequired)
    async def _sign_in(_request: Request, exc: SignInRequired) -> RedirectResponse:
        return RedirectResponse(f"/login?next={quote(exc.next_path)}", status_code=303)


def _render(request: Request, name: str, status_code: int = 200, **ctx: Any) -> HTMLResponse:
    ctx.setdefault("user", None)
    # the session's CSRF token for the page's forms (empty when signed in by a key header,
    # which needs none)
    ctx.setdefault("csrf_token", getattr(request.state, "csrf_token", ""))
    return templates.TemplateResponse(request, name, ctx, status_code=status_code)


def _safe_next(path: str) -> str:
    return path if path.startswith("/") and not path.startswith("//") else "/"


# --- sign-in --------------------------------------------------------------------------------
@router.get("/login", response_class=HTMLResponse)
def login_page(request: Request, next: str = "/") -> HTMLResponse:
    return _render(request, "login.html", next=_safe_next(next), error=None)


def _same_origin(request: Request) -> bool:
    """Whether a form was posted from this site. Against login CSRF: a form on another site
    could sign the browser in under the attacker's key, and what the victim then uploads
    would be the attacker's. Browsers send Origin with every cross-site POST (Referer in
    older ones; "null" when hidden, which is refused); a request with neither comes from a
    client that is not a browser, which no other site can drive."""
    source = request.headers.get("origin") or request.headers.get("referer")
    return source is None or urlsplit(source).netloc == request.headers.get("host")


@router.post("/login", response_class=HTMLResponse)
def login(
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    key: Annotated[str, Form()],
    next: Annotated[str, Form()] = "/",
) -> Response:
    """Check the key and start a session: the cookie holds a random token, the database its
    hash. The key is checked in the database, not the key cache: a key revoked or rotated a
    moment ago must not open a session that outlives the cache."""
    target = _safe_next(next)
    if not _same_origin(request):
        msg = "sign-in refused: the form was posted from another site"
        return _render(request, "login.html", 403, next=target, error=msg)
    if settings.auth == "off":
        return RedirectResponse(target, status_code=303)
    user = user_for_key(session, key.strip())
    if user is None:
        return _render(request, "login.html", 401, next=target, error="unknown API key")
    token, _ = create_web_session(session, user.id, settings.session_ttl_s)
    resp = RedirectResponse(target, status_code=303)
    # SameSite=Lax, not Strict: a link to a job page from elsewhere (mail, the viewer) opens
    # signed in; every unsafe request needs the CSRF token anyway.
    resp.set_cookie(
        SESSION_COOKIE, token, max_age=settings.session_ttl_s, httponly=True,
        secure=settings.cookie_secure, samesite="lax",
    )  # fmt: skip
    resp.delete_cookie(OLD_KEY_COOKIE)  # a raw key left by an older version: gone
    return resp


@router.post("/logout")
def logout(
    request: Request,
    session: SessionDep,
    settings: SettingsDep,
    csrf_token: Annotated[str | None, Form(alias=CSRF_FIELD)] = None,
) -> RedirectResponse:
    """End the session (its row is deleted: the same cookie is refused from now on, on every
    server process) and clear the cookie; the form must carry the session's CSRF token."""
    token = request.cookies.get(SESSION_COOKIE)
    live = web_session_user(session, token) if token else None
    if live is not None:
        require_csrf(request.headers.get(CSRF_HEADER) or csrf_token, live[1])
        delete_web_session(session, token)
    resp = RedirectResponse("/login", status_code=303)
    resp.delete_cookie(SESSION_COOKIE, httponly=True, secure=settings.cookie_secure, samesite="lax")
    return resp


# --- jobs -----------------------------------------------------------------------------------
def _worlds(session, user: Principal) -> list[WorldOut]:
    return worlds_api.list_worlds(session, user)


def _jobs_page(request, session, user, error: str | None = None, status_code: int = 200):
    page = jobs_api.list_jobs(session, user, None, None, 100, 0)
    worlds = _worlds(session, user)
    names = {w.id: w.name for w in worlds}
    refresh = any(j.status in ACTIVE for j in page.items)
    return _render(
        request, "jobs.html", status_code, user=user, jobs=page.items, total=page.total,
        worlds=worlds, world_names=names, refresh=refresh, error=error,
    )  # fmt: skip


@router.get("/", response_class=HTMLResponse)
def jobs_page(request: Request, session: SessionDep, user: PageUser) -> HTMLResponse:
    """Jobs with status and progress bars (refreshing while any runs); a submit form."""
    return _jobs_page(request, session, user)


@router.post("/jobs", response_class=HTMLResponse)
def submit_job_form(
    request: Request,
    session: SessionDep,
    user: PageUser,
    settings: SettingsDep,
    world_id: Annotated[int, Form()],
    runs: Annotated[int, Form()] = 1,
    slam: Annotated[str, Form()] = "rbpf",
    time_limit: Annotated[float | None, Form()] = None,
) -> Response:
    """Submit through the API's own handler; errors come back on the page."""
    params: dict[str, Any] = {}
    if time_limit is not None:
        params["explore"] = {"time_limit": time_limit}
    try:
        body = JobIn(world_id=world_id, runs=runs, slam=slam, params=params)
        job = jobs_api.submit(session, user, settings, body, None)
    except ValidationError as exc:
        msg = "; ".join(e["msg"] for e in exc.errors())
        return _jobs_page(request, session, user, f"invalid job: {msg}", 400)
    except (HTTPException, InputError) as exc:
        session.rollback()
        code = 429 if getattr(exc, "status_code", 400) == 429 else 400  # 429: over a quota
        return _jobs_page(request, session, user, str(getattr(exc, "detail", exc)), code)
    return RedirectResponse(f"/jobs/{job.id}", status_code=303)


@router.get("/jobs/{job_id}", response_class=HTMLResponse)
def job_page(
    request: Request, job_id: IdPath, session: SessionDep, user: PageUser, settings: SettingsDep
) -> HTMLResponse:
    """A job's runs: outcome, coverage, errors, plots, downloads and the live-view link."""
    from backend.viewer_tokens import issue, signing_key
    from frontend.viewer import run_link

    job = owned(user, session.get(Job, job_id), "job", job_id)
    # each viewer link carries a fresh token for its run and this user (it expires)
    key = signing_key(settings.database_url, settings.secret_key)
    runs = []
    for r in job.runs:
        token = issue(key, r.id, user.id, settings.viewer_token_ttl_s)
        runs.append(_run_row(r, run_link(settings.viewer_url, r.id, token)))
    return _render(
        request, "job.html", user=user, job=job, world=session.get(World, job.world_id),
        runs=runs, refresh=job.status in ACTIVE,
    )  # fmt: skip


def _run_row(run: Run, viewer_link: str) -> dict[str, Any]:
    summary = RunSummary.load(run.summary)
    b = summary.relations.get("B") if summary else None
    report = bool(run.report_dir) and Path(run.report_dir).is_dir()
    return {
        "run": run,
        "b": b,
        "report": report,
        "errors_plot": report and (Path(run.report_dir) / "errors.png").is_file(),
        "viewer": viewer_link,
        "pct": round(100 * float((run.progress or {}).get("coverage", 0.0))),
    }


@router.get("/runs/{run_id}/plot/{name}.png")
def run_plot(run_id: IdPath, name: str, session: SessionDep, user: PageUser) -> Response:
    """The run's trajectories or errors plot: the report's file, else drawn from the database."""
    from backend.store import load_trajectory, world_occupancy
    from worker.report.plots import trajectories_png

    if name not in ("trajectories", "errors"):
        raise HTTPException(404, f"no plot {name!r}")
    run = owned(user, session.get(Run, run_id), "run", run_id)
    if run.status != "done":
        raise HTTPException(404, f"run {run_id} is {run.status}: no results yet")
    if run.report_dir and (Path(run.report_dir) / f"{name}.png").is_file():
        return Response((Path(run.report_dir) / f"{name}.png").read_bytes(), media_type="image/png")
    if name == "errors":
        raise HTTPException(404, f"run {run_id} has no report folder with its errors")
    w = session.get_one(World, run.world_id)
    _, gt = load_trajectory(session, run_id, "gt")
    _, est = load_trajectory(session, run_id, "est")
    buf = io.BytesIO()
    trajectories_png(
        buf, world_occupancy(w), w.resolution, (w.origin_x, w.origin_y), gt, est,
        f"{w.name}, seed {run.seed}, {run.slam}: {run.outcome}",
    )  # fmt: skip
    return Response(buf.getvalue(), media_type="image/png")


# --- worlds ---------------------------------------------------------------------------------
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


def _worlds_page(request, session, user, error=None, notice=None, status_code=200):
    worlds = _worlds(session, user)
    # reload until every analysis is done; not an error page, which answers a POST (a reload
    # would send the form again)
    refresh = error is None and any(w.status == "pending" for w in worlds)
    return _render(
        request, "worlds.html", status_code, user=user, worlds=worlds,
        error=error, notice=notice, fact_labels=FACT_LABELS, refresh=refresh,
    )  # fmt: skip


_STATE = {"pending": "is being analysed", "ready": "is ready", "invalid": "is invalid"}


@router.get("/worlds", response_class=HTMLResponse)
def worlds_page(
    request: Request,
    session: SessionDep,
    user: PageUser,
    uploaded: int | None = None,
    again: bool = False,
) -> HTMLResponse:
    """Worlds as thumbnails with their facts; an upload form. After an upload (`uploaded`),
    a notice says where that world stands."""
    notice = None
    w = session.get(World, uploaded) if uploaded is not None else None
    if w is not None and (user.is_admin or w.owner_id == user.id):
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
    """Upload through the API's own handler; its answer (or its error) is shown on the page."""
    try:
        res = float(resolution) if resolution.strip() else None
    except ValueError:
        res = -1.0
    if res is not None and not res > 0:
        msg = f"the resolution must be a positive number of metres per pixel, not {resolution!r}"
        return _worlds_page(request, session, user, msg, None, 400)
    try:
        names = worlds_api.checked_names(file)
        files = {name: f.file.read() for name, f in zip(names, file, strict=True)}
        row, fresh = worlds_api.accept_upload(session, user, settings, files, res)
    except (HTTPException, InputError) as exc:
        session.rollback()
        msg = str(getattr(exc, "detail", exc))
        return _worlds_page(request, session, user, msg, None, getattr(exc, "status_code", 400))
    session.commit()  # the analysis runs in another process: it must see the row
    if fresh:
        world_pool(request.app).submit(row.id)
    # POST, redirect, GET: the page then reloads itself while the world is pending
    again = "" if fresh else "&again=1"
    return RedirectResponse(f"/worlds?uploaded={row.id}{again}", status_code=303)


# --- compare --------------------------------------------------------------------------------
@router.get("/compare", response_class=HTMLResponse)
def compare_page(request: Request, session: SessionDep, user: PageUser) -> HTMLResponse:
    """Success and B errors per world (thesis Tables 6.4, 6.5) and error bars (Figs. 6.8, 6.9)."""
    rows = stats_api.stats(session, user, "world")
    counts = _relation_counts(session, user)
    for row in rows:
        row["relations"] = counts.get(row["world_id"], 0)
    return _render(request, "compare.html", user=user, rows=rows)


def _relation_counts(session, user: Principal) -> dict[int, int]:
    """Per world: B relations evaluated over its completed runs."""
    stmt = select(Run.world_id, Run.summary).where(Run.status == "done", Run.outcome == "completed")
    if not user.is_admin:
        stmt = stmt.where(Run.owner_id == user.id)
    out: dict[int, int] = {}
    for wid, summary in session.execute(stmt):
        b = (s := RunSummary.load(summary)) and s.relations.get("B")
        out[wid] = out.get(wid, 0) + (b.translation.n if b else 0)
    return out


@router.get("/compare/{kind}.png")
def compare_plot(kind: str, session: SessionDep, user: PageUser) -> Response:
    """Mean B error per world with a 1-std error bar and the min-max range."""
    if kind not in ("translation", "rotation"):
        raise HTTPException(404, f"no chart {kind!r}")
    rows = [r for r in stats_api.stats(session, user, "world") if r[kind]["mean"] is not None]
    buf = io.BytesIO()
    error_bar_chart(buf, rows, kind)
    return Response(buf.getvalue(), media_type="image/png")


def error_bar_chart(out, rows: list[dict], kind: str) -> None:
    """Thesis Figs. 6.8/6.9: per world, mean +- std (bar) and min..max (thin line)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    unit = "m" if kind == "translation" else "rad"
    fig, ax = plt.subplots(figsize=(max(5.0, 0.9 * len(rows) + 2), 3.6), dpi=100)
    x = list(range(len(rows)))
    mean = [r[kind]["mean"] for r in rows]
    std = [r[kind]["std"] for r in rows]
    lo = [r[kind]["mean"] - r[kind]["min"] for r in rows]
    hi = [r[kind]["max"] - r[kind]["mean"] for r in rows]
    ax.errorbar(x, mean, yerr=[lo, hi], fmt="none", ecolor="#999999", elinewidth=1, capsize=3)
    ax.errorbar(x, mean, yerr=std, fmt="o", color="#1f5fbf", elinewidth=2.5, capsize=5)
    ax.set_xticks(x, [r["world"] for r in rows], rotation=30, ha="right", fontsize=8)
    ax.set_ylabel(f"mean {kind} error [{unit}]")
    ax.set_title(f"B relations, {kind}: mean ± std (blue), min–max (grey)", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    ax.set_ylim(bottom=0.0)
    if not rows:
        ax.text(0.5, 0.5, "no completed runs yet", ha="center", transform=ax.transAxes)
    fig.tight_layout()
    fig.savefig(out, format="png")
    plt.close(fig)
