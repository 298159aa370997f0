"""The dashboard's comparison page: success and B errors per world (thesis Tables 6.4, 6.5)
and their error-bar charts (Figs. 6.8, 6.9), drawn with matplotlib; and the algorithms side by
side per world with their paired comparison on the same seeds (worker.batch.paired)."""

from __future__ import annotations

import io

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, Response
from sqlalchemy import select

from backend.api.deps import SessionDep
from backend.db.models import Run, World
from backend.services import stats as stats_service
from backend.services.access import Principal
from frontend.dashboard.explore_data import DEFAULT_KINDS, outcome_kind
from frontend.dashboard.pages import PageUser, render
from worker.batch.paired import Sample, paired_diffs
from worker.report.summary import RunSummary
from worker.status import RunOutcome, RunStatus

router = APIRouter(include_in_schema=False)


@router.get("/compare", response_class=HTMLResponse)
def compare_page(request: Request, session: SessionDep, user: PageUser) -> HTMLResponse:
    """Success and B errors per world (thesis Tables 6.4, 6.5) and error bars (Figs. 6.8, 6.9)."""
    rows = stats_service.per_world(session, user)
    counts = _relation_counts(session, user)
    for row in rows:
        row["relations"] = counts.get(row["world_id"], 0)
    by_slam, samples = _per_algorithm(session, user)
    paired = [d.as_row() for d in paired_diffs(samples)]
    estimates = _estimate_rows(session, user)
    return render(request, "compare.html", user=user, rows=rows, by_slam=by_slam, paired=paired,
                  estimates=estimates)  # fmt: skip


def _per_algorithm(session, user: Principal) -> tuple[list[dict], list[Sample]]:
    """Per world and algorithm: runs done, completed, and the mean of the scored runs' mean B
    translational error; and each scored run's score for the paired comparison. A run counts
    with its scores when it completed, gave up frontiers (incomplete) or hit its time limit
    (the explorer's default; it can leave any kind out): outcome and scores are separate."""
    stmt = (
        select(World.name, Run.slam, Run.seed, Run.outcome, Run.reason, Run.b_mean_t)
        .join(World, Run.world_id == World.id)
        .where(Run.status == RunStatus.DONE)
    )
    if not user.is_admin:
        stmt = stmt.where(Run.owner_id == user.id)
    cells: dict[tuple[str, str], dict] = {}
    samples: list[Sample] = []
    for name, slam, seed, outcome, reason, b_t in session.execute(stmt):
        cell = cells.setdefault((name, slam), {"world": name, "slam": slam, "runs": 0, "b": [],
                                               "completed": 0, "time_limit": 0})  # fmt: skip
        cell["runs"] += 1
        kind = outcome_kind(outcome, reason)
        cell["completed"] += kind == "completed"
        if kind in DEFAULT_KINDS and b_t is not None:
            cell["b"].append(b_t)
            cell["time_limit"] += kind == "time limit"
            samples.append(Sample(name, slam, seed, b_t))
    rows = []
    for key in sorted(cells):
        c = cells[key]
        mean = sum(c["b"]) / len(c["b"]) if c["b"] else None
        rows.append({"world": c["world"], "slam": c["slam"], "runs": c["runs"],
                     "completed": c["completed"], "scored": len(c["b"]),
                     "time_limited": c["time_limit"], "b_mean_t": mean})  # fmt: skip
    return rows, samples


def _estimate_rows(session, user: Principal) -> list[dict]:
    """Per external algorithm (`mapqual score`, POST /runs/{id}/estimates): its mean B errors
    over the runs it was scored on, beside those of the runs' own algorithms on the very same
    runs and relations."""
    from backend.db.models import RunEstimate

    stmt = select(RunEstimate.name, RunEstimate.b_mean_t, RunEstimate.b_mean_r, Run.slam,
                  Run.b_mean_t, Run.b_mean_r).join(Run, Run.id == RunEstimate.run_id)  # fmt: skip
    if not user.is_admin:
        stmt = stmt.where(Run.owner_id == user.id)
    groups: dict[str, list] = {}
    for name, et, er, slam, ot, orr in session.execute(stmt):
        groups.setdefault(name, []).append((et, er, slam, ot, orr))

    def mean(values) -> float | None:
        vals = [v for v in values if v is not None]
        return sum(vals) / len(vals) if vals else None

    return [
        {
            "name": name,
            "runs": len(g),
            "t": mean(x[0] for x in g),
            "r": mean(x[1] for x in g),
            "own": ", ".join(sorted({x[2] for x in g})),
            "own_t": mean(x[3] for x in g),
            "own_r": mean(x[4] for x in g),
        }  # fmt: skip
        for name, g in sorted(groups.items())
    ]


def _relation_counts(session, user: Principal) -> dict[int, int]:
    """Per world: B relations evaluated over its completed runs."""
    stmt = select(Run.world_id, Run.summary).where(
        Run.status == RunStatus.DONE, Run.outcome == RunOutcome.COMPLETED
    )
    if not user.is_admin:
        stmt = stmt.where(Run.owner_id == user.id)
    out: dict[int, int] = {}
    for wid, summary in session.execute(stmt):
        b = (s := RunSummary.load(summary)) and s.relations.get("B")
        out[wid] = out.get(wid, 0) + (b.translation.n if b else 0)
    return out


@router.get("/compare/{kind}.png")
def compare_plot(kind: str, session: SessionDep, user: PageUser) -> Response:
    """Mean B error per world with a 1-std error bar and the min-max range; or (paired) each
    pair of algorithms' mean per-seed difference with its 95 % confidence interval."""
    if kind == "paired":
        buf = io.BytesIO()
        paired_chart(buf, [d.as_row() for d in paired_diffs(_per_algorithm(session, user)[1])])
        return Response(buf.getvalue(), media_type="image/png")
    if kind not in ("translation", "rotation"):
        raise HTTPException(404, f"no chart {kind!r}")
    rows = [r for r in stats_service.per_world(session, user) if r[kind]["mean"] is not None]
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


def paired_chart(out, rows: list[dict]) -> None:
    """Per world and pair of algorithms: the mean per-seed difference of mean B error (A - B)
    with its confidence interval as the error bar (a dot alone: one pair, no interval)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 1.6 + 0.45 * max(len(rows), 1)), dpi=100)
    y = list(range(len(rows)))
    for k, r in enumerate(rows):
        lo = r["mean_diff"] - r["ci_low"] if r["ci_low"] is not None else 0.0
        hi = r["ci_high"] - r["mean_diff"] if r["ci_high"] is not None else 0.0
        ax.errorbar([r["mean_diff"]], [k], xerr=[[lo], [hi]], fmt="o", color="#1f5fbf", capsize=4)
    ax.axvline(0.0, color="#999999", lw=1)
    ax.set_yticks(y, [f"{r['group']}: {r['a']} − {r['b']} (n={r['n']})" for r in rows], fontsize=8)
    ax.set_xlabel("A − B, mean B translational error [m] (left of 0: A lower)", fontsize=8)
    ax.invert_yaxis()
    ax.set_title("paired per-seed difference, 95 % confidence interval", fontsize=9)
    ax.grid(axis="x", alpha=0.3)
    if not rows:
        ax.text(0.5, 0.5, "no two algorithms on a common seed yet", ha="center",
                transform=ax.transAxes)  # fmt: skip
    fig.tight_layout()
    fig.savefig(out, format="png")
    plt.close(fig)
