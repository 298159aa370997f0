"""bench_validity's report: Spearman's rho between relation errors and map scores, the
agreement with the thesis's rule of thumb, bootstrap intervals, and the scatter plot."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

# Thesis 6.3.4: a map is visually bad above these mean B errors.
BAD_T = 1.0  # [m]
BAD_R = 0.03  # [rad]
SCORES = ("distance_m", "distance_map_m", "distance_floorplan_m", "precision", "recall",
          "wall_coverage", "free_share")  # fmt: skip
ERRORS = (("B", "translation"), ("B", "rotation"), ("A", "translation"), ("A", "rotation"),
          ("SM", "translation"), ("SM", "rotation"))  # fmt: skip
# The same relations scored on the SLAM's final trajectory (rbpf: its best particle's path at
# the end), the one the final map was drawn along; an algorithm that keeps none (odometry)
# has only its online estimate, which is then its final one.
FINAL_KINDS = ("B", "SM")
ERRORS_FINAL = tuple((f"{kind}final", axis) for kind in FINAL_KINDS
                     for axis in ("translation", "rotation"))  # fmt: skip


def column(rows: list[dict[str, Any]], name: str) -> np.ndarray:
    return np.array([np.nan if r[name] is None else r[name] for r in rows], dtype=float)


def spearman_table(rows: list[dict[str, Any]]) -> list[tuple[str, dict[str, tuple[float, int]]]]:
    """(error, {score: (rho, n)}) for every relation error and map score."""
    from scipy.stats import spearmanr

    table = []
    for kind, axis in ERRORS + ERRORS_FINAL:
        err = column(rows, f"{kind}_{axis}")
        cells = {}
        for score in SCORES:
            sc = column(rows, score)
            ok = np.isfinite(err) & np.isfinite(sc)
            rho = spearmanr(err[ok], sc[ok]).statistic if ok.sum() >= 3 else math.nan
            cells[score] = (float(rho), int(ok.sum()))
        table.append((f"{kind} {axis}", cells))
    return table


def agreement(
    rows: list[dict[str, Any]], threshold: float, b: str = "B"
) -> tuple[int, int, int, int]:
    """(agree, n, bad by the thesis's rule, bad by the map score): the rule of thumb (mean B
    above 1 m or 0.03 rad is bad; `b` "B" the online estimate's, "Bfinal" the final
    trajectory's) against the map score (distance above `threshold` is bad)."""
    bt, br = column(rows, f"{b}_translation"), column(rows, f"{b}_rotation")
    dist = column(rows, "distance_m")
    ok = np.isfinite(bt) & np.isfinite(br) & np.isfinite(dist)
    bad_rule = (bt[ok] > BAD_T) | (br[ok] > BAD_R)
    bad_map = dist[ok] > threshold
    return int(np.sum(bad_rule == bad_map)), int(ok.sum()), int(bad_rule.sum()), int(bad_map.sum())


def best_threshold(rows: list[dict[str, Any]], b: str = "B") -> float:
    """The distance threshold that agrees best with the rule of thumb (fitted on these runs)."""
    dist = np.sort(column(rows, "distance_m")[np.isfinite(column(rows, "distance_m"))])
    if len(dist) == 0:
        return math.nan
    cands = np.concatenate(([dist[0] - 1e-9], 0.5 * (dist[1:] + dist[:-1]), [dist[-1]]))
    return float(max(cands, key=lambda t: (agreement(rows, t, b)[0], -t)))


def bootstrap_rho(
    x: np.ndarray, y: np.ndarray, resamples: int = 2000, seed: int = 0
) -> tuple[float, float]:
    """95 % percentile interval of Spearman's rho of (x, y) over the runs resampled with
    replacement (nan where fewer than 3 finite pairs)."""
    from scipy.stats import spearmanr

    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if len(x) < 3:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    rhos = []
    for _ in range(resamples):
        i = rng.integers(0, len(x), len(x))
        rho = spearmanr(x[i], y[i]).statistic
        if np.isfinite(rho):  # a resample of one repeated run has no rank order
            rhos.append(rho)
    lo, hi = np.percentile(rhos, [2.5, 97.5])
    return float(lo), float(hi)


def report(rows: list[dict[str, Any]], tolerance: float, b: str = "B") -> str:
    """The figures as text (what the README quotes); `b` the B error of the medians and the
    rule of thumb ("B" online, "Bfinal" final trajectory)."""
    lines = [f"{len(rows)} runs with B errors and a map score"]
    by = {}
    for r in rows:
        by.setdefault(r["slam"], []).append(r)
    for slam, rs in by.items():
        bt, d = column(rs, f"{b}_translation"), column(rs, "distance_m")
        lines.append(f"  {slam:9s} {len(rs):3d} runs: median B {np.nanmedian(bt):.3f} m, "
                     f"median wall distance {np.nanmedian(d):.3f} m")  # fmt: skip
    lines.append("Spearman's rho, mean relation error against map score (n runs):")
    lines.append("  " + " ".join(f"{s:>20s}" for s in ("error",) + SCORES))
    for name, cells in spearman_table(rows):
        cols = " ".join(f"{rho:>14.3f} ({n:3d})" for rho, n in cells.values())
        lines.append(f"  {name:>20s} {cols}")
    dist = column(rows, "distance_m")
    for kind, label in (("B", "online estimate"), ("Bfinal", "final trajectory")):
        lo, hi = bootstrap_rho(column(rows, f"{kind}_translation"), dist)
        lines.append(
            f"  {kind} translation ({label}) against distance_m: 95 % bootstrap "
            f"interval {lo:.3f} .. {hi:.3f} (2,000 resamples of the runs, seed 0)"
        )
    lines.append("The same within each laser-noise level (noise blurs the map's walls, whatever")
    lines.append("the trajectory; B, A, SM translation against distance_m / precision):")
    for noise in sorted({r["noise"] for r in rows}):
        sub = [r for r in rows if r["noise"] == noise]
        cells = dict(spearman_table(sub))
        parts = [
            f"{kind} {cells[f'{kind} translation']['distance_m'][0]:+.3f} / "
            f"{cells[f'{kind} translation']['precision'][0]:+.3f}"
            for kind in ("B", "Bfinal", "A", "SM")
        ]
        lines.append(f"  noise {noise:g} m ({len(sub)} runs): " + ", ".join(parts))
    for label, thr in (("a priori, the tolerance", tolerance), ("fitted", best_threshold(rows, b))):
        agree, n, bad_rule, bad_map = agreement(rows, thr, b)
        lines.append(f"rule of thumb vs wall distance > {thr:.3f} m ({label}): {agree}/{n} "
                     f"runs agree (bad: {bad_rule} by the rule, {bad_map} by the map)")  # fmt: skip
    return "\n".join(lines)


def scatter(rows: list[dict[str, Any]], path: Path, b: str = "B") -> None:
    """B error (`b`: "B" online, "Bfinal" final trajectory) against the wall distance, the
    precision and the free share, one colour per SLAM variant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.stats import spearmanr

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8), dpi=100)
    marks = {0.0: "o", 0.1: "s", 0.3: "^"}
    colours = {"rbpf-40": "#1a9e1a", "rbpf-10": "#1f5fbf", "rbpf-3": "#bf8f1f",
               "rbpf-1": "#d62020", "odometry": "#555555"}  # fmt: skip
    panels = (("distance_m", "symmetric wall distance [m]"),
              ("precision", "wall precision (0.1 m)"),
              ("free_share", "free share of the reachable floorplan"))  # fmt: skip
    for ax, (score, label) in zip(axes, panels, strict=True):
        for r in rows:
            if r[f"{b}_translation"] is None or r[score] is None:
                continue
            ax.scatter(r[f"{b}_translation"], r[score], c=colours.get(r["slam"], "k"),
                       marker=marks.get(r["noise"], "x"), s=30, alpha=0.8)  # fmt: skip
        bt, sc = column(rows, f"{b}_translation"), column(rows, score)
        ok = np.isfinite(bt) & np.isfinite(sc)
        rho = spearmanr(bt[ok], sc[ok]).statistic if ok.sum() >= 3 else math.nan
        ax.set_xscale("log")
        if score == "distance_m":
            ax.set_yscale("log")
        ax.axvline(BAD_T, color="k", lw=0.8, ls="--")
        which = "final trajectory" if b == "Bfinal" else "online estimate"
        ax.set_xlabel(f"mean B translational error [m], {which}")
        ax.set_ylabel(label)
        ax.set_title(f"Spearman rho = {rho:.2f} ({ok.sum()} runs)", fontsize=10)
        ax.grid(alpha=0.3, which="both")
    for slam, c in colours.items():
        axes[0].scatter([], [], c=c, label=slam)
    for noise, m in marks.items():
        axes[0].scatter([], [], c="w", edgecolors="k", marker=m, label=f"noise {noise:g} m")
    axes[0].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
