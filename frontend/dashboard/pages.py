"""The dashboard's sign-in and job pages, and what every page shares: server-rendered (Jinja2)
over the same handlers and access rules as the REST API; a browser signs in with its API key
and then holds a session cookie."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Annotated, Any
from urllib.parse import quote, urlsplit

from fastapi import APIRouter, Depends, Form, Header, HTTPException, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from fastapi.templating import Jinja2Templates
from pydantic import ValidationError

from backend.api.artifacts import maybe_files, serve
from backend.api.deps import (
    CSRF_FIELD,
    CSRF_HEADER,
    SESSION_COOKIE,
    IdPath,
    SessionDep,
    SettingsDep,
    current_user,
    require_csrf,
)
from backend.core.schemas import JobIn, WorldOut
from backend.db.models import Run, World
from backend.services import jobs as jobs_service
from backend.services import runs as runs_service
from backend.services import users
from backend.services import worlds as worlds_service
from backend.services.access import Principal
from backend.services.errors import QuotaExceeded, ServiceError
from frontend.dashboard.explore_data import group, job_result, load_runs, settings_used
from worker.errors import InputError
from worker.explore.params import ExploreParams
from worker.report.summary import RunSummary
from worker.slam import registry
from worker.status import ACTIVE_JOB, FINISHED_RUN, RunStatus, WorldStatus

HERE = Path(__file__).resolve().parent
templates = Jinja2Templates(directory=HERE / "templates")
# the statuses as the templates compare against them (no string literals there either)
templates.env.globals.update(
    RunStatus=RunStatus, WorldStatus=WorldStatus, FINISHED_RUN=FINISHED_RUN
)
# the job form's choices: what a run can use (the replay-only third-party programs replay
# recorded logs with `mapqual slam`, they cannot drive a robot)
templates.env.globals["slam_algorithms"] = lambda: tuple(
    e for e in registry.entries() if not e.replay_only
)
templates.env.globals["job_result"] = job_result  # the jobs list's result column
templates.env.globals["zoom_dpi"] = 220  # the plots' zoom view (explore_plots.ZOOM_DPI)
router = APIRouter(include_in_schema=False)
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


async def sign_in_redirect(_request: Request, exc: SignInRequired) -> RedirectResponse:
    """The answer to a page asked for without a valid key: the sign-in page, then back."""
    return RedirectResponse(f"/login?next={quote(exc.next_path)}", status_code=303)


def render(request: Request, name: str, status_code: int = 200, **ctx: Any) -> HTMLResponse:
    """Template `name` with `ctx`, the signed-in user and the session's CSRF token."""
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
    return render(request, "login.html", next=_safe_next(next), error=None)


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
        return render(request, "login.html", 403, next=target, error=msg)
    if settings.auth == "off":
        return RedirectResponse(target, status_code=303)
    token = users.sign_in(session, key.strip(), settings.session_ttl_s)
    if token is None:
        return render(request, "login.html", 401, next=target, error="unknown API key")
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
    live = users.session_user(session, token) if token else None
    if live is not None:
        require_csrf(request.headers.get(CSRF_HEADER) or csrf_token, live[1])
        users.sign_out(session, token)
    resp = RedirectResponse("/login", status_code=303)
    resp.delete_cookie(SESSION_COOKIE, httponly=True, secure=settings.cookie_secure, samesite="lax")
    return resp


# --- jobs -----------------------------------------------------------------------------------
def user_worlds(session, user: Principal) -> list[WorldOut]:
    """The worlds `user` may see, as the API lists them."""
    return worlds_service.list_worlds(session, user)


def _jobs_page(request, session, user, settings, error: str | None = None, status_code: int = 200):
    page = jobs_service.list_jobs(session, user, limit=100)
    worlds = user_worlds(session, user)
    names = {w.id: w.name for w in worlds}
    refresh = any(j.status in ACTIVE_JOB for j in page.items)
    return render(
        request, "jobs.html", status_code, user=user, jobs=page.items, total=page.total,
        worlds=worlds, world_names=names, refresh=refresh, error=error,
        external_programs=sorted(settings.external_slam),  # the form's external:NAME choices
        default_time_limit=ExploreParams().time_limit,  # what an empty field means
    )  # fmt: skip


@router.get("/", response_class=HTMLResponse)
def jobs_page(
    request: Request, session: SessionDep, user: PageUser, settings: SettingsDep
) -> HTMLResponse:
    """Jobs with status and progress bars (refreshing while any runs); a submit form."""
    return _jobs_page(request, session, user, settings)


@router.post("/jobs", response_class=HTMLResponse)
def submit_job_form(
    request: Request,
    session: SessionDep,
    user: PageUser,
    settings: SettingsDep,
    world_id: Annotated[int, Form()],
    runs: Annotated[int, Form()] = 1,
    slam: Annotated[list[str], Form(max_length=8)] = ["rbpf"],  # noqa: B006
    time_limit: Annotated[float | None, Form()] = None,
    seeds: Annotated[str, Form(max_length=2000)] = "",
) -> Response:
    """Submit through the jobs service, as the API does; errors come back on the page. Several
    algorithms make one job that runs each on every seed (the seeds field, else 1..runs)."""
    params: dict[str, Any] = {}
    if time_limit is not None:
        params["explore"] = {"time_limit": time_limit}
    try:
        names = []
        for label in slam:
            name, program = registry.parse_label(label)  # external:NAME: an admin's program
            if program is not None:
                if len(slam) > 1:
                    raise InputError("an external program runs alone: pick it without others")
                params["slam"] = {"external": {"name": program}}
            names.append(name)
        chosen = {"slam": names[0]} if len(names) == 1 else {"algorithms": names}
        count = {"seeds": parse_seeds(seeds)} if seeds.strip() else {"runs": runs}
        body = JobIn(world_id=world_id, params=params, **chosen, **count)
        job = jobs_service.submit(session, user, settings, body, None)
    except ValidationError as exc:
        msg = "; ".join(e["msg"] for e in exc.errors())
        return _jobs_page(request, session, user, settings, f"invalid job: {msg}", 400)
    except (ServiceError, InputError) as exc:
        session.rollback()
        code = 429 if isinstance(exc, QuotaExceeded) else 400  # 429: over a quota
        detail = str(exc)
        return _jobs_page(request, session, user, settings, detail, code)
    return RedirectResponse(f"/jobs/{job.id}", status_code=303)


def parse_seeds(text: str) -> list[int]:
    """ "1-5, 8 10" -> [1, 2, 3, 4, 5, 8, 10]; InputError (a 400 on the page) for anything else,
    a range of more than 1000 seeds or a seed above 2^31 - 1."""
    out: list[int] = []
    for token in text.replace(",", " ").split():
        lo, sep, hi = token.partition("-")
        if not lo.isdigit() or (sep and not hi.isdigit()) or len(token) > 21:
            raise InputError(f"seeds: {token[:30]!r} is not a seed or a range like 1-5")
        a, b = int(lo), int(hi) if sep else int(lo)
        if b < a or b - a >= 1000 or b > 2**31 - 1:
            raise InputError(f"seeds: the range {token[:30]!r} is empty or too long")
        out.extend(range(a, b + 1))
        if len(out) > 1000:
            raise InputError("seeds: at most 1000 per job")
    return out


@router.get("/jobs/{job_id}", response_class=HTMLResponse)
def job_page(
    request: Request, job_id: IdPath, session: SessionDep, user: PageUser, settings: SettingsDep
) -> HTMLResponse:
    """A job's runs: outcome, coverage, errors, plots, downloads and the live-view link."""
    from backend.core.viewer_tokens import issue, signing_key
    from frontend.viewer import run_link

    job = jobs_service.job_of(session, user, job_id)
    # each viewer link carries a fresh token for its run and this user (it expires)
    key = signing_key(settings.database_url, settings.secret_key)
    runs = []
    for r in job.runs:
        token = issue(key, r.id, user.id, settings.viewer_token_ttl_s)
        runs.append(_run_row(r, run_link(settings.viewer_url, r.id, token)))
    _add_estimates(session, runs)
    done = load_runs(session, user, job_id)
    return render(
        request, "job.html", user=user, job=job, world=session.get(World, job.world_id),
        runs=runs, refresh=job.status in ACTIVE_JOB, groups=group(done, ("slam", "setting")),
        used=settings_used(job.runs[0].params if job.runs else None), n_done=len(done),
        algorithms=sorted({r.slam for r in job.runs}), paired=_job_paired(done),
    )  # fmt: skip


def _job_paired(done: list) -> list[dict]:
    """The job's algorithms against each other on its seeds, per setting (scored runs that
    completed, gave up frontiers or hit their time limit)."""
    from frontend.dashboard.explore_data import DEFAULT_KINDS
    from worker.batch.paired import Sample, paired_diffs

    samples = [Sample(r.setting, r.slam, r.seed, r.b_t) for r in done
               if r.b_t is not None and r.kind in DEFAULT_KINDS]  # fmt: skip
    return [d.as_row() for d in paired_diffs(samples)]


def _run_row(run: Run, viewer_link: str) -> dict[str, Any]:
    summary = RunSummary.load(run.summary)
    b = summary.relations.get("B") if summary else None
    files = maybe_files(run)  # only links to files that can be served now
    names = set(files.names()) if files is not None else set()
    return {
        "run": run,
        "b": b,
        "report": files is not None,
        "relations": {k for k in ("A", "B", "SM") if f"relations_{k}.txt" in names},
        "names": names,
        "errors_plot": "errors.png" in names,
        "map_score": summary.map_score if summary else None,  # issue 17: map vs floorplan
        "realtime": summary.realtime if summary else None,  # issue 51: real-time SLAM
        "overlay_plot": "map_overlay.png" in names,
        "viewer": viewer_link,
        "pct": round(100 * float((run.progress or {}).get("coverage", 0.0))),
    }


def _add_estimates(session, rows: list[dict[str, Any]]) -> None:
    """Each run row's algorithms, (name, relation summaries by kind): its own, then the external
    estimates scored on its relations; and whether it has a sim.log to export as a bag."""
    from backend.services.estimates import estimates_of_runs
    from worker.export.bag import SIM_LOG_NAMES

    by_run: dict[int, list] = {}
    for e in estimates_of_runs(session, [row["run"].id for row in rows]):
        by_run.setdefault(e.run_id, []).append(e)
    for row in rows:
        run = row["run"]
        own = (run.metrics or {}).get("relations") or {}
        row["algorithms"] = [(f"{run.slam} (this run)", own)] + [
            (e.name, (e.metrics or {}).get("relations") or {}) for e in by_run.get(run.id, [])
        ]
        row["bag"] = any(n in row["names"] for n in SIM_LOG_NAMES)


@router.get("/runs/{run_id}/plot/{name}.png")
def run_plot(run_id: IdPath, name: str, session: SessionDep, user: PageUser) -> Response:
    """The run's trajectories, errors or map-overlay plot: the report's file, else (trajectories
    only) drawn from the database."""
    from worker.report.plots import trajectories_png

    if name not in ("trajectories", "errors", "map_overlay"):
        raise HTTPException(404, f"no plot {name!r}")
    run = runs_service.done_run(session, user, run_id)
    files = maybe_files(run)
    if files is not None and files.has(f"{name}.png"):
        return serve(files, f"{name}.png", "image/png", run_id, inline=True)
    if name in ("errors", "map_overlay"):
        raise HTTPException(404, f"run {run_id} has no report folder with its {name} plot")
    w = session.get_one(World, run.world_id)
    _, gt = runs_service.trajectory(session, run_id, "gt")
    _, est = runs_service.trajectory(session, run_id, "est")
    buf = io.BytesIO()
    trajectories_png(
        buf, worlds_service.occupancy(w), w.resolution, (w.origin_x, w.origin_y), gt, est,
        f"{w.name}, seed {run.seed}, {run.slam}: {run.outcome}",
    )  # fmt: skip
    return Response(buf.getvalue(), media_type="image/png")
