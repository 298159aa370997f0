"""A batch's figures: errors per world (thesis Figs. 6.8, 6.9), furniture against none
(Fig. 6.3), success and error against laser noise (Figs. 6.4-6.6), A against B errors."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from worker.batch.records import GOOD_R, GOOD_T, BatchRecord, is_good, outcome_of, relation_stats
from worker.batch.tables import error_rows
from worker.status import RunOutcome

AXES = (("translation", "m", GOOD_T), ("rotation", "rad", GOOD_R))
DPI = 110


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def errors_by_world(records: Sequence[BatchRecord], path: Path) -> Path | None:
    """Per environment: mean B error with its standard deviation as an error bar (left axis)
    and the max error as a line (right axis), averaged over completed runs."""
    rows = {axis: error_rows(records, axis) for axis, _, _ in AXES}
    if not rows["translation"]:
        return None
    plt = _plt()
    n = len(rows["translation"])
    fig, axs = plt.subplots(2, 1, figsize=(max(6.0, 0.45 * n + 2.5), 7.5), constrained_layout=True)
    # no threshold line here: beside the max on its own axis it would read against the wrong one
    for ax, (axis, unit, _) in zip(axs, AXES, strict=True):
        r = rows[axis]
        x = np.arange(len(r))
        mean = [row["MEAN"] for row in r]
        std = [row["STD"] for row in r]
        ax.errorbar(x, mean, yerr=std, fmt="o", capsize=4, label="mean ± std")
        ax.set_ylabel(f"B {axis} error [{unit}]")
        ax.set_ylim(bottom=0)
        ax2 = ax.twinx()
        ax2.plot(x, [row["MAX"] for row in r], color="tab:orange", marker="s", label="max")
        ax2.set_ylabel(f"max {axis} error [{unit}]", color="tab:orange")
        ax2.set_ylim(bottom=0)
        ax.set_xticks(x, [row["ENVIRONMENT"] for row in r], rotation=60, ha="right", fontsize=8)
        lines = ax.get_legend_handles_labels()
        more = ax2.get_legend_handles_labels()
        ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, loc="best")
        ax.grid(axis="y", alpha=0.3)
    axs[0].set_title("B-relation errors per environment (completed runs)")
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _mean_std(recs: Sequence[BatchRecord], axis: str) -> tuple[float, float, int]:
    """Average over completed runs of each run's mean and std B error, and how many runs."""
    stats = [
        getattr(b, axis)
        for r in recs
        if outcome_of(r)[0] == RunOutcome.COMPLETED and (b := relation_stats(r))
    ]
    if not stats:
        return float("nan"), float("nan"), 0
    return (
        float(np.mean([s.mean for s in stats])),
        float(np.mean([s.std for s in stats])),
        len(stats),
    )


def furniture(records: Sequence[BatchRecord], path: Path) -> Path | None:
    """Environments present in both variants (at the lowest noise): mean B error ± std."""
    low = min((r["noise"] for r in records), default=0.0)
    pairs: dict[str, dict[str, list]] = {}
    for r in records:
        if r["noise"] == low:
            pairs.setdefault(r["base"], {}).setdefault(r["variant"], []).append(r)
    bases = [b for b, v in pairs.items() if {"furniture", "no_furniture"} <= set(v)]
    if not bases:
        return None
    plt = _plt()
    fig, axs = plt.subplots(
        2, 1, figsize=(max(6.0, 0.7 * len(bases) + 2.5), 7.5), constrained_layout=True
    )
    x = np.arange(len(bases))
    for ax, (axis, unit, _) in zip(axs, AXES, strict=True):
        for dx, variant, color in (
            (-0.15, "no_furniture", "tab:blue"),
            (0.15, "furniture", "tab:red"),
        ):
            ms = [_mean_std(pairs[b][variant], axis) for b in bases]
            ax.errorbar(
                x + dx, [m for m, _, _ in ms], yerr=[s for _, s, _ in ms], fmt="o", capsize=4,
                color=color, label=variant.replace("_", " "),
            )  # fmt: skip
        ax.set_xticks(x, bases, rotation=45, ha="right", fontsize=8)
        ax.set_xlim(-0.6, len(bases) - 0.4)
        ax.set_ylabel(f"B {axis} error [{unit}]")
        ax.set_ylim(bottom=0)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(fontsize=8)
    axs[0].set_title(f"Without and with furniture (completed runs, noise {low:g} m)")
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def noise(records: Sequence[BatchRecord], path: Path) -> Path | None:
    """For each world and algorithm run at several noise levels: share of completed runs, and
    mean B translational and rotational error of the completed runs, against the noise."""
    series: dict[tuple[str, str], dict[float, list]] = {}
    for r in records:
        series.setdefault((r["world"], r["slam"]), {}).setdefault(r["noise"], []).append(r)
    series = {k: v for k, v in series.items() if len(v) > 1}
    if not series:
        return None
    plt = _plt()
    fig, axs = plt.subplots(1, 3, figsize=(14, 4.2), constrained_layout=True)
    slams = {slam for _, slam in series}
    for (world, slam), by_noise in series.items():
        levels = sorted(by_noise)
        label = world if len(slams) == 1 else f"{world} ({slam})"
        done = [
            np.mean([outcome_of(r)[0] == RunOutcome.COMPLETED for r in by_noise[n]]) for n in levels
        ]
        axs[0].plot(levels, 100 * np.asarray(done), marker="o", label=label)
        for ax, (axis, _, _) in zip(axs[1:], AXES, strict=True):
            ms = [_mean_std(by_noise[n], axis) for n in levels]
            ax.errorbar(levels, [m for m, _, _ in ms], yerr=[s for _, s, _ in ms], marker="o",
                        capsize=4, label=label)  # fmt: skip
    axs[0].set_ylabel("completed runs [%]")
    axs[0].set_ylim(-5, 105)
    for ax, (axis, unit, good) in zip(axs[1:], AXES, strict=True):
        ax.set_ylabel(f"B {axis} error [{unit}] (completed runs)")
        ax.axhline(good, color="grey", ls="--", lw=1)
        ax.set_ylim(bottom=0)
    for ax in axs:
        ax.set_xlabel("laser noise sigma [m]")
        ax.grid(alpha=0.3)
    axs[0].legend(fontsize=8)
    fig.suptitle("Success and error against laser range noise")
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def a_vs_b(records: Sequence[BatchRecord], path: Path) -> Path | None:
    """Each run's mean A error against its mean B error, good runs apart from bad ones: A
    relations (local consistency) barely separate them, B relations do (thesis 6.1)."""
    pts = [(r, a, b) for r in records if (a := relation_stats(r, "A")) and (b := relation_stats(r))]
    if not pts:
        return None
    plt = _plt()
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, axs = plt.subplots(1, 2, figsize=(11, 4.6), constrained_layout=True)
    classes = (
        ("good map", "tab:green", lambda r: is_good(r)),
        ("bad map (B over the limit)", "tab:red", lambda r: _bad(r)),
        ("not completed", "tab:grey", lambda r: outcome_of(r)[0] != RunOutcome.COMPLETED),
    )
    for ax, (axis, unit, good), floor in zip(axs, AXES, (1e-5, 1e-6), strict=True):
        for label, color, member in classes:
            sel = [(getattr(b, axis).mean, getattr(a, axis).mean) for r, a, b in pts if member(r)]
            if sel:
                xs, ys = np.maximum(np.asarray(sel), floor).T  # zeros drawn on the floor
                ax.scatter(xs, ys, s=22, color=color, alpha=0.8, label=f"{label} ({len(sel)})")
        ax.axvline(good, color="grey", ls="--", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        for a in (ax.xaxis, ax.yaxis):
            # labels at 1, 2, 5 x 10^k only: the default labels every minor tick of a short
            # log span, and they run into each other
            a.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
            a.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
            a.set_minor_formatter(NullFormatter())
        ax.set_xlabel(f"mean B {axis} error [{unit}] (log; floor {floor:g})")
        ax.set_ylabel(f"mean A {axis} error [{unit}] (log; floor {floor:g})")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle("Mean A against mean B error per run (good map: B under 1 m and 0.03 rad)")
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path


def _bad(rec: BatchRecord) -> bool:
    return outcome_of(rec)[0] == RunOutcome.COMPLETED and not is_good(rec)


FIGURES = {
    "errors_by_world.png": errors_by_world,
    "furniture.png": furniture,
    "noise.png": noise,
    "a_vs_b.png": a_vs_b,
}


def write_plots(records: Sequence[BatchRecord], out: Path) -> dict[str, Path | None]:
    """Every figure the records allow (None where the batch has no data for it)."""
    result = {}
    for name, fn in FIGURES.items():
        target = out / name
        target.unlink(missing_ok=True)  # a figure this batch cannot draw must not linger
        result[name] = fn(records, target)
    return result
