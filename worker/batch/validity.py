"""Does the map score agree with the relations? Spearman's rho of a batch's runs' mean B errors
against their map-versus-floorplan scores, pooled and per laser-noise level, and a scatter plot
(issue 17 section 4, on the batch's own runs)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from worker.batch.records import GOOD_T, BatchRecord, relation_stats, summary_of

# (label, map_score field): the scores ranked against the B errors
SCORES = (("wall distance", "distance_m"), ("precision", "precision"), ("recall", "recall"))
MIN_RUNS = 3  # Spearman's rho needs at least this many runs
PLOT = "validity.png"


def points(records: Sequence[BatchRecord]) -> list[dict[str, Any]]:
    """One point per run with B relations and a map score: its noise, slam, errors, scores."""
    out = []
    for rec in records:
        s, b = summary_of(rec), relation_stats(rec)
        if s is None or b is None or s.map_score is None:
            continue
        pt = {"noise": float(rec["noise"]), "slam": rec["slam"],
              "b_t": b.translation.mean, "b_r": b.rotation.mean}  # fmt: skip
        pt.update({f: getattr(s.map_score, f) for _, f in SCORES})
        out.append(pt)
    return out


def _rho(pts: Sequence[dict[str, Any]], err: str, score: str) -> float | None:
    from scipy.stats import spearmanr

    e = np.array([p[err] for p in pts if p[score] is not None], dtype=float)
    sc = np.array([p[score] for p in pts if p[score] is not None], dtype=float)
    if len(e) < MIN_RUNS or np.ptp(e) == 0 or np.ptp(sc) == 0:
        return None
    rho = float(spearmanr(e, sc).statistic)
    return None if math.isnan(rho) else rho


def rho_rows(pts: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows of rho (B translation and rotation against each score): all runs, then per noise."""
    groups = [("all runs", list(pts))]
    noises = sorted({p["noise"] for p in pts})
    if len(noises) > 1:
        groups += [(f"noise {n:g} m", [p for p in pts if p["noise"] == n]) for n in noises]
    rows = []
    for label, sub in groups:
        row: dict[str, Any] = {"group": label, "runs": len(sub)}
        for name, field in SCORES:
            row[f"t {name}"] = _rho(sub, "b_t", field)
            row[f"r {name}"] = _rho(sub, "b_r", field)
        rows.append(row)
    return rows


def columns() -> list[str]:
    """The rho table's columns, in order."""
    return ["group", "runs"] + [f"{a} {n}" for a in ("t", "r") for n, _ in SCORES]


def scatter(pts: Sequence[dict[str, Any]], path: Path) -> Path | None:
    """B translational error against the wall distance, one marker per noise level."""
    pts = [p for p in pts if p["distance_m"] is not None and p["b_t"] > 0 and p["distance_m"] > 0]
    if len(pts) < MIN_RUNS:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6), dpi=100)
    slams = sorted({p["slam"] for p in pts})
    colours = dict(zip(slams, plt.cm.tab10(np.arange(len(slams)) % 10), strict=True))
    marks = "os^vDP*X"
    for i, n in enumerate(sorted({p["noise"] for p in pts})):
        for slam in slams:
            sub = [p for p in pts if p["noise"] == n and p["slam"] == slam]
            if sub:
                ax.scatter([p["b_t"] for p in sub], [p["distance_m"] for p in sub], s=30,
                           color=colours[slam], marker=marks[i % len(marks)], alpha=0.8,
                           label=f"{slam}, noise {n:g} m")  # fmt: skip
    ax.set_xscale("log")
    ax.set_yscale("log")
    if max(p["b_t"] for p in pts) >= GOOD_T:
        ax.axvline(GOOD_T, color="k", lw=0.8, ls="--")
    ax.set_xlabel("mean B translational error [m]")
    ax.set_ylabel("map wall distance to the floorplan [m]")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def validity(records: Sequence[BatchRecord], out: Path) -> dict[str, Any] | None:
    """The report's validity section (rho table, scatter plot written to OUT), None when fewer
    than MIN_RUNS runs have both B errors and a map score."""
    pts = points(records)
    if len(pts) < MIN_RUNS:
        return None
    return {"rows": rho_rows(pts), "columns": columns(), "plot": scatter(pts, out / PLOT)}
