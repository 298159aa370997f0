"""The explorer's plots of selected groups, large and on shared axes: scores as box plots with
every run's point (time-limited runs marked), success rates with their intervals, the pose
error over time, and ground-truth paths coloured by the pose error along them (as evo does)."""

from __future__ import annotations

from collections.abc import Callable
from contextvars import ContextVar
from typing import Any

import numpy as np

from frontend.dashboard.explore_data import SCORE_NAMES, SCORES, Group

DPI = 110  # the pages' plots; the zoom view asks for ZOOM_DPI, sharp when enlarged
ZOOM_DPI = 220  # pages.templates' zoom_dpi
MAX_DPI = 300
# the resolution of the plot being drawn (the route sets it from its `dpi` parameter)
RENDER_DPI: ContextVar[int] = ContextVar("RENDER_DPI", default=DPI)
RUNS_PER_GROUP = 10  # error-over-time curves drawn per group
# outcome kind -> (marker, colour) of a run's point
MARKERS = {"completed": ("o", "#1f5fbf"), "incomplete": ("s", "#2ca02c"),
           "time limit": ("X", "#d62728"), "failed": ("v", "#7f7f7f")}  # fmt: skip


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _empty(ax, text: str = "no runs selected") -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes)


def _save(fig, out) -> None:
    fig.tight_layout()
    fig.savefig(out, format="png", dpi=RENDER_DPI.get())
    _plt().close(fig)


def scores_png(out, groups: list[Group], _session: Any = None) -> None:
    """B, A and SM errors: per group a box (quartiles, whiskers at 1.5 IQR) and every run's
    point, shaped by its outcome, on one x axis per score."""
    plt = _plt()
    width = max(10.0, 1.3 * len(groups) + 4)
    fig, axes = plt.subplots(2, 2, figsize=(width, 8.5), sharex=True)
    rng = np.random.default_rng(0)  # the jitter only: the same picture every time
    for ax, score in zip(axes.ravel(), SCORES, strict=True):
        data = [[getattr(r, score) for r in g.runs if getattr(r, score) is not None]
                for g in groups]  # fmt: skip
        if any(data):
            ax.boxplot([d if d else [np.nan] for d in data], positions=range(len(groups)),
                       widths=0.5, showfliers=False)  # fmt: skip
        for kind, (marker, colour) in MARKERS.items():  # one call per kind: fast with many
            pts = [(i, getattr(r, score)) for i, g in enumerate(groups) for r in g.runs
                   if r.kind == kind and getattr(r, score) is not None]  # fmt: skip
            if pts:
                xs, ys = np.array(pts, dtype=float).T
                xs += rng.uniform(-0.15, 0.15, len(xs))
                ax.scatter(xs, ys, marker=marker, c=colour, s=30, alpha=0.8, label=kind,
                           zorder=3)  # fmt: skip
        ax.set_ylabel(SCORE_NAMES[score])
        ax.grid(axis="y", alpha=0.3)
        ax.set_ylim(bottom=0.0)
        if not groups:
            _empty(ax)
        elif not any(data):
            _empty(ax, "no run of the selection has this score")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    seen = dict(zip(labels, handles, strict=True))
    if seen:
        fig.legend(seen.values(), seen.keys(), loc="upper right", title="outcome")
    for ax in axes[1]:
        ax.set_xticks(range(len(groups)), [_wrap(g.label) for g in groups], rotation=20,
                      ha="right", fontsize=9)  # fmt: skip
    fig.suptitle("Mean relation error per run: box = quartiles, points = runs", fontsize=12)
    _save(fig, out)


def _wrap(label: str, width: int = 28) -> str:
    parts, line = [], ""
    for word in label.split(" "):
        if len(line) + len(word) > width and line:
            parts.append(line)
            line = ""
        line += (" " if line else "") + word
    return "\n".join([*parts, line])


def success_png(out, groups: list[Group], _session: Any = None) -> None:
    """Success rate (completed / runs shown) per group with its Wilson 95 % interval."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(max(8.0, 1.1 * len(groups) + 3), 4.5))
    for i, g in enumerate(groups):
        lo, hi = g.success
        rate = g.success_rate
        ax.errorbar([i], [rate], yerr=[[rate - lo], [hi - rate]], fmt="o", capsize=6, ms=8)
        ax.annotate(f"{g.completed}/{len(g.runs)}", (i, rate), textcoords="offset points",
                    xytext=(10, 0), va="center")  # fmt: skip
    ax.set_xticks(range(len(groups)), [_wrap(g.label) for g in groups], rotation=20,
                  ha="right", fontsize=9)  # fmt: skip
    ax.set_ylim(-0.02, 1.05)
    ax.set_ylabel("success rate (completed / runs)")
    ax.set_title("Success rate with its 95 % Wilson interval")
    ax.grid(axis="y", alpha=0.3)
    if not groups:
        _empty(ax)
    _save(fig, out)


def _pose_error(session, run_id: int) -> tuple[np.ndarray, np.ndarray]:
    """(t, |gt - est|) [s, m]: the recorded estimate against the ground truth, unaligned."""
    from backend.services.runs import trajectory

    t, gt = trajectory(session, run_id, "gt")
    _, est = trajectory(session, run_id, "est")
    n = min(len(gt), len(est))
    return t[:n], np.hypot(*(gt[:n, :2] - est[:n, :2]).T)


def error_time_png(out, groups: list[Group], session: Any) -> None:
    """Pose error over time, every run of a group in its colour, all on the same axes."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(12, 5))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, g in enumerate(groups):
        for j, r in enumerate(sorted(g.runs, key=lambda r: r.seed)[:RUNS_PER_GROUP]):
            t, e = _pose_error(session, r.id)
            label = g.label if j == 0 else None
            ax.plot(t, e, color=colours[i % len(colours)], lw=1.0, alpha=0.75, label=label)
    ax.set_xlabel("simulated time [s]")
    ax.set_ylabel("pose error |gt − estimate| [m] (unaligned)")
    ax.set_title(f"Pose error over time (up to {RUNS_PER_GROUP} runs per group, lowest seeds)")
    ax.grid(alpha=0.3)
    ax.set_ylim(bottom=0.0)
    if groups:
        ax.legend(fontsize=8)
    else:
        _empty(ax)
    _save(fig, out)


def paths_png(out, groups: list[Group], session: Any) -> None:
    """Per group, its lowest seed's ground-truth path over the floorplan, coloured by the pose
    error along it on one colour scale for all panels (as evo's trajectory plots)."""
    from matplotlib.collections import LineCollection

    from backend.db.models import Run, World
    from backend.services.runs import trajectory
    from backend.services.worlds import occupancy

    plt = _plt()
    n = max(1, len(groups))
    cols = min(n, 3)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 5.0 * rows), squeeze=False)
    drawn = []
    for ax, g in zip(axes.ravel(), groups, strict=False):
        r = min(g.runs, key=lambda r: r.seed)
        run = session.get(Run, r.id)
        w = session.get(World, run.world_id)
        occ = occupancy(w)
        h, wd = occ.shape
        x0, y0, res = w.origin_x, w.origin_y, w.resolution
        ext = (x0, x0 + wd * res, y0, y0 + h * res)
        ax.imshow(occ, cmap="Greys", origin="lower", extent=ext, vmin=0, vmax=1.6)
        _, gt = trajectory(session, r.id, "gt")
        t, e = _pose_error(session, r.id)
        pts = gt[: len(e), :2]
        segs = np.stack((pts[:-1], pts[1:]), axis=1)
        drawn.append((ax, segs, e[1:]))
        ax.set_title(f"{_wrap(g.label, 40)}\nseed {r.seed}, run #{r.id}", fontsize=9)
        ax.set_aspect("equal")
    top = max([float(e.max()) for *_, e in drawn if len(e)] or [1.0])
    for ax, segs, e in drawn:
        lc = LineCollection(segs, cmap="viridis", norm=plt.Normalize(0.0, top), linewidths=2)
        lc.set_array(e)
        ax.add_collection(lc)
    for ax in axes.ravel()[len(groups) :]:
        ax.axis("off")
    if drawn:
        fig.colorbar(lc, ax=axes.ravel().tolist(), label="pose error [m] (unaligned)")
    else:
        _empty(axes[0, 0])
    fig.savefig(out, format="png", dpi=RENDER_DPI.get())
    plt.close(fig)


PLOTS: dict[str, Callable[..., None]] = {
    "scores": scores_png,
    "success": success_png,
    "error_time": error_time_png,
    "paths": paths_png,
}
