"""The results explorer page: every run as a row with its changed parameters as columns,
filters, group-by (world x algorithm x setting) with mean, spread and 95 % intervals, and the
comparison of selected groups (box plots with per-seed points, success rates, the paired
comparison on common seeds, pose error over time, paths coloured by their error); every table
as CSV and every plot as PNG."""

from __future__ import annotations

import csv
import io
from typing import Annotated
from urllib.parse import urlencode

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, Response

from backend.api.deps import SessionDep
from frontend.dashboard import explore_plots
from frontend.dashboard.explore_data import (
    DEFAULT_KINDS,
    GROUP_KEYS,
    KINDS,
    SCORE_NAMES,
    SCORES,
    Filters,
    Group,
    RunRow,
    group,
    load_runs,
    param_columns,
)
from frontend.dashboard.pages import PageUser, render
from worker.batch.paired import Sample, paired_diffs

router = APIRouter(include_in_schema=False)
MAX_SELECTED = 12  # groups compared at once: more is unreadable on one plot
Names = Annotated[list[Annotated[str, Query(max_length=300)]], Query(max_length=200)]


def _filters(world: list[str], slam: list[str], setting: list[str], kind: list[str],
             by: list[str], applied: bool, job: list[str] = ()) -> Filters:  # fmt: skip
    bad = [k for k in kind if k not in KINDS] + [b for b in by if b not in GROUP_KEYS]
    bad += [j for j in job if not (j.isdigit() and len(j) < 19)]
    if bad:
        raise HTTPException(400, f"unknown filter value(s): {', '.join(sorted(set(bad)))[:200]}")
    kinds = tuple(kind) if applied else DEFAULT_KINDS  # a submitted form may leave all out
    group_by = tuple(k for k in GROUP_KEYS if k in by) if applied else GROUP_KEYS
    jobs = tuple(int(j) for j in job)
    return Filters(tuple(world), tuple(slam), tuple(setting), kinds, group_by, jobs)


class View:
    """The runs, filters, groups and selection of one request."""

    def __init__(self, session, user, world, slam, setting, kind, by, g, applied: bool,
                 job: list[str]):  # fmt: skip
        self.all = load_runs(session, user)
        self.filters = _filters(world, slam, setting, kind, by, applied, job)
        self.rows = self.filters.apply(self.all)
        self.groups = group(self.rows, self.filters.group_by)
        wanted = set(g)
        chosen = [x for x in self.groups if x.ident in wanted]
        # nothing chosen: compare every group when they fit on a plot
        self.selected = chosen or (self.groups if len(self.groups) <= MAX_SELECTED else [])
        self.selected = self.selected[:MAX_SELECTED]

    def paired(self) -> list[dict]:
        """Algorithms against each other on the same world, setting and seeds (selected runs)."""
        samples = [
            Sample(f"{r.world} · {r.setting}", r.slam, r.seed, r.b_t)
            for x in self.selected
            for r in x.runs
            if r.b_t is not None
        ]
        return [d.as_row() for d in paired_diffs(samples)]


def _view(request: Request, session, user, world, slam, setting, kind, by, g) -> View:
    applied = request.query_params.get("applied") == "1"
    job = request.query_params.getlist("job")[:200]
    return View(session, user, world, slam, setting, kind, by, g, applied, job)


@router.get("/explore", response_class=HTMLResponse)
def explore_page(request: Request, session: SessionDep, user: PageUser, world: Names = [],  # noqa: B006
                 slam: Names = [], setting: Names = [], kind: Names = [], by: Names = [],  # noqa: B006
                 g: Names = []) -> HTMLResponse:  # noqa: B006  # fmt: skip
    """The explorer: filters, groups (select and compare), the comparison, the runs."""
    v = _view(request, session, user, world, slam, setting, kind, by, g)
    query = str(request.url.query)
    sel = [("g", x.ident) for x in v.selected]
    plot_query = urlencode([(k, val) for k, val in request.query_params.multi_items()
                            if k != "g"] + sel)  # fmt: skip
    choices = {
        "world": sorted({r.world for r in v.all}),
        "slam": sorted({r.slam for r in v.all}),
        "setting": sorted({r.setting for r in v.all}),
    }
    return render(
        request, "explore.html", user=user, view=v, f=v.filters, choices=choices, kinds=KINDS,
        group_keys=GROUP_KEYS, params=param_columns(v.rows), scores=SCORES,
        score_names=SCORE_NAMES, paired=v.paired(), query=query, plot_query=plot_query,
        selected={x.ident for x in v.selected}, runs_shown=v.rows[:RUNS_SHOWN],
    )  # fmt: skip


RUNS_SHOWN = 500  # rows of the runs table in the page (sorted by id; the CSV has all)


@router.get("/explore/runs.csv")
def runs_csv(request: Request, session: SessionDep, user: PageUser, world: Names = [],  # noqa: B006
             slam: Names = [], setting: Names = [], kind: Names = [], by: Names = [],  # noqa: B006
             g: Names = []) -> Response:  # noqa: B006  # fmt: skip
    """The filtered runs, one row each, with every changed parameter as a column."""
    v = _view(request, session, user, world, slam, setting, kind, by, g)
    return _csv("runs.csv", runs_table(v.rows))


@router.get("/explore/groups.csv")
def groups_csv(request: Request, session: SessionDep, user: PageUser, world: Names = [],  # noqa: B006
               slam: Names = [], setting: Names = [], kind: Names = [], by: Names = [],  # noqa: B006
               g: Names = []) -> Response:  # noqa: B006  # fmt: skip
    """The groups with n, mean, std and the 95 % interval of each score, and success rates."""
    v = _view(request, session, user, world, slam, setting, kind, by, g)
    return _csv("groups.csv", groups_table(v.groups))


@router.get("/explore/plot/{name}.png")
def explore_plot(name: str, request: Request, session: SessionDep, user: PageUser,
                 world: Names = [], slam: Names = [], setting: Names = [],  # noqa: B006
                 kind: Names = [], by: Names = [], g: Names = [],  # noqa: B006
                 dpi: Annotated[int, Query(ge=50, le=explore_plots.MAX_DPI)] = explore_plots.DPI,
                 ) -> Response:  # fmt: skip
    """A plot of the selected groups: scores (box plots with per-seed points), success rates,
    pose error over time, or paths coloured by their error; `dpi` for the zoom view's sharper
    copy."""
    draw = explore_plots.PLOTS.get(name)
    if draw is None:
        raise HTTPException(404, f"no plot {name!r}")
    v = _view(request, session, user, world, slam, setting, kind, by, g)
    buf = io.BytesIO()
    token = explore_plots.RENDER_DPI.set(dpi)
    try:
        draw(buf, v.selected, session)
    finally:
        explore_plots.RENDER_DPI.reset(token)
    headers = {"Content-Disposition": f'inline; filename="{name}.png"'}
    return Response(buf.getvalue(), media_type="image/png", headers=headers)


def runs_table(rows: list[RunRow]) -> list[list]:
    params = param_columns(rows)
    head = ["run", "job", "world", "algorithm", "seed", "setting", *params, "outcome", "reason",
            "coverage", *SCORES]  # fmt: skip
    out: list[list] = [head]
    for r in rows:
        out.append([r.id, r.job_id, r.world, r.slam, r.seed, r.setting,
                    *[r.changed.get(p, "") for p in params], r.outcome, r.reason or "",
                    _num(r.coverage), *[_num(getattr(r, s)) for s in SCORES]])  # fmt: skip
    return out


def groups_table(groups: list[Group]) -> list[list]:
    by = groups[0].by if groups else GROUP_KEYS
    head = [*by, "runs", "completed", "success_rate", "success_low", "success_high"]
    for s in ("coverage", *SCORES):
        head += [f"{s}_n", f"{s}_mean", f"{s}_std", f"{s}_ci_low", f"{s}_ci_high"]
    out: list[list] = [head]
    for x in groups:
        row = [*x.key, len(x.runs), x.completed, _num(x.success_rate), *map(_num, x.success)]
        for st in (x.coverage, *(x.scores[s] for s in SCORES)):
            row += [st.n, _num(st.mean), _num(st.std), _num(st.low), _num(st.high)]
        out.append(row)
    return out


def _num(v) -> str:
    return "" if v is None else repr(float(v))


def _csv(name: str, table: list[list]) -> Response:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    for row in table:
        w.writerow([_cell(c) for c in row])
    headers = {"Content-Disposition": f'attachment; filename="{name}"'}
    return Response(buf.getvalue(), media_type="text/csv; charset=utf-8", headers=headers)


def _cell(c) -> str:
    """A CSV cell a spreadsheet will not run as a formula (a world name is the user's)."""
    s = str(c)
    return "'" + s if s[:1] in ("=", "+", "-", "@") and not _is_number(s) else s


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True
