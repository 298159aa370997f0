"""Draw an exploration run to PNG: floorplan, final SLAM map, paths (gt green, est red), goals."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

_GOAL_COLOURS = {
    "reached": "tab:blue",
    "explored": "tab:cyan",
    "failed": "tab:orange",
    "replaced": "0.6",
    "dropped": "0.6",
}


def render_run(world, result, path: str | Path, title: str | None = None, dpi: int = 110) -> Path:
    """Write a two-panel PNG: left the floorplan with both paths and the goals, right the final
    SLAM map (placed in the world by the coverage alignment) with the estimated path.

    world: worker.world.World; result: ExplorationResult. Returns the path written.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    h, w = world.occ.shape
    extent = (
        world.origin[0],
        world.origin[0] + w * world.resolution,
        world.origin[1],
        world.origin[1] + h * world.resolution,
    )
    aspect = (extent[1] - extent[0]) / max(extent[3] - extent[2], 1e-9)
    fig, axes = plt.subplots(1, 2, figsize=(2 * 6.0, 6.0 / aspect + 0.8), squeeze=True)
    ax0, ax1 = axes
    ax0.imshow(~world.occ, cmap="gray", origin="lower", extent=extent, vmin=0, vmax=1)
    ax0.plot(result.pose_gt[:, 0], result.pose_gt[:, 1], "-", color="tab:green", lw=0.9,
             label="ground truth")  # fmt: skip
    est_w = _to_world(result.T_world_map, result.pose_est[:, :2])
    ax0.plot(est_w[:, 0], est_w[:, 1], "-", color="tab:red", lw=0.6, label="SLAM estimate")
    for g in result.goals:
        gw = _to_world(result.T_world_map, np.array([[g.x, g.y]]))[0]
        ax0.plot(gw[0], gw[1], "o", ms=3, color=_GOAL_COLOURS.get(g.status, "k"))
    ax0.plot(*result.pose_gt[0, :2], "g^", ms=7)
    if result.collision is not None:
        ax0.plot(result.collision[1], result.collision[2], "rx", ms=12, mew=2.5)
    ax0.set_title("floorplan, paths, goals (blue reached, orange failed)", fontsize=8)
    ax0.legend(loc="lower right", fontsize=7)
    _draw_map(ax1, result)
    head = title or getattr(world, "name", "run")
    fig.suptitle(
        f"{head}: {result.outcome} ({result.reason}), coverage {100 * result.coverage:.1f} %, "
        f"t = {result.t[-1]:.0f} s, path {result.path_length_m:.0f} m, "
        f"goals {result.goals_reached} ok / {result.goals_failed} failed",
        fontsize=9,
    )
    for ax in axes:
        ax.set_aspect("equal")
        ax.tick_params(labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def _draw_map(ax, result) -> None:
    grid = result.final_map
    img = np.full(grid.prob.shape, 0.8)
    known = ~np.isnan(grid.prob)
    img[known] = np.where(grid.prob[known] > grid.occ_thresh, 0.0, 1.0)
    h, w = img.shape
    ext = (
        grid.origin[0],
        grid.origin[0] + w * grid.resolution,
        grid.origin[1],
        grid.origin[1] + h * grid.resolution,
    )
    ax.imshow(img, cmap="gray", origin="lower", extent=ext, vmin=0, vmax=1)
    ax.plot(result.pose_est[:, 0], result.pose_est[:, 1], "-", color="tab:red", lw=0.6)
    ax.set_title("final SLAM map (map frame), estimated path", fontsize=8)


def _to_world(T: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Map-frame points `(K, 2)` into the world by T_world_map `(3,)`."""
    c, s = math.cos(T[2]), math.sin(T[2])
    return np.column_stack((T[0] + c * xy[:, 0] - s * xy[:, 1], T[1] + s * xy[:, 0] + c * xy[:, 1]))
