"""Report images: the map with its errors written on it (thesis Fig. 5.3), trajectories, errors."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import BinaryIO

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from worker.slam.grid import ros_to_image


def _font(size: int) -> ImageFont.ImageFont | ImageFont.FreeTypeFont:
    return ImageFont.load_default(size=size)


def map_png(
    path: str | Path | BinaryIO, grid_ros: np.ndarray, lines: Sequence[str], min_width: int = 640
):
    """Write the map with `lines` of text on it in a box at the top left.

    Small maps are scaled up by an integer factor (nearest neighbour) so that the text stays
    readable and every map cell remains a crisp square of pixels.
    """
    grey = ros_to_image(grid_ros)
    scale = max(1, int(np.ceil(min_width / max(grey.shape[1], 1))))
    img = Image.fromarray(grey, mode="L").convert("RGB")
    if scale > 1:
        img = img.resize((img.width * scale, img.height * scale), Image.Resampling.NEAREST)
    draw = ImageDraw.Draw(img, "RGBA")
    font = _font(max(12, img.width // 45))
    pad = 6
    boxes = [draw.textbbox((0, 0), s, font=font) for s in lines]
    line_h = max((b[3] - b[1] for b in boxes), default=0) + 4
    box_w = max((b[2] - b[0] for b in boxes), default=0) + 2 * pad
    if lines:
        draw.rectangle((0, 0, box_w, line_h * len(lines) + 2 * pad), fill=(255, 255, 255, 215))
        for i, s in enumerate(lines):
            draw.text((pad, pad + i * line_h), s, fill=(160, 0, 0), font=font)
    img.save(path, format="PNG")  # explicit: `path` may be a stream


def _floorplan_axes(
    ax, occ: np.ndarray, resolution: float, origin: Sequence[float], max_across: int
) -> None:
    """Draw the floorplan (walls dark) in world coordinates; `occ` is `[iy, ix]`, bottom first.

    A plan more than `max_across` cells wide is drawn from blocks of k x k cells (k = its
    width // max_across), a block dark where any of its cells is a wall: the figure cannot
    show more (max_across is twice the figure's width in pixels), and its memory stays that
    of a plan max_across wide. Narrower plans are drawn cell for cell."""
    import matplotlib

    occ = np.asarray(occ, dtype=np.bool_)
    k = max(1, occ.shape[1] // max_across)
    if k > 1:
        occ = wall_blocks(occ, k)
    h, w = occ.shape
    size = k * resolution  # [m] a drawn cell
    extent = (origin[0], origin[0] + w * size, origin[1], origin[1] + h * size)
    # the two colours looked up once and the plan drawn as (H, W, 4) bytes, the same pixels:
    # from a plan of values matplotlib makes (H, W, 4) float64 colours and copies of them
    # (the figure took 142 MiB on virginia_cross's 1.7 M cells, 78 MiB this way)
    colours = matplotlib.colormaps["gray"]([1.0, 0.25], bytes=True)
    ax.imshow(colours[occ.view(np.uint8)], origin="lower", extent=extent, interpolation="nearest")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal")


def wall_blocks(occ: np.ndarray, k: int) -> np.ndarray:
    """`(ceil(H / k), ceil(W / k)) bool`: each k x k block of `occ (H, W) bool` a wall where any
    of its cells is one (the last row and column of blocks padded with free cells)."""
    h, w = occ.shape
    hb, wb = -(-h // k), -(-w // k)
    padded = np.zeros((hb * k, wb * k), dtype=np.bool_)
    padded[:h, :w] = occ
    return padded.reshape(hb, k, wb, k).any(axis=(1, 3))


def trajectories_png(
    path: str | Path,
    occ: np.ndarray,
    resolution: float,
    origin: Sequence[float],
    pose_gt: np.ndarray,
    pose_est: np.ndarray,
    title: str = "",
) -> None:
    """Ground truth (green) and estimate (red) over the floorplan; `(N, 3)` poses in metres."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h, w = occ.shape
    fig_w, dpi = 9.0, 110
    fig, ax = plt.subplots(figsize=(fig_w, max(3.0, fig_w * h / max(w, 1))), dpi=dpi)
    _floorplan_axes(ax, occ, resolution, origin, max_across=int(2 * fig_w * dpi))
    ax.plot(pose_gt[:, 0], pose_gt[:, 1], color="#1a9e1a", lw=2.8, label="ground truth")
    ax.plot(pose_est[:, 0], pose_est[:, 1], color="#d62020", lw=1.3, label="estimate")
    if len(pose_gt):
        ax.plot(*pose_gt[0, :2], "o", color="black", ms=5, label="start")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def errors_png(
    path: str | Path,
    t2: np.ndarray,
    err_trans: np.ndarray,
    err_rot: np.ndarray,
    title: str = "B-relation errors along the run",
) -> None:
    """Each relation's translational and rotational error at the later of its two times."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_t, ax_r) = plt.subplots(2, 1, figsize=(9, 5.5), dpi=110, sharex=True)
    order = np.argsort(t2)
    # a few relations (B relations are often a handful) must stay visible; thousands must not
    # hide each other
    size, alpha = (3, 0.35) if len(t2) > 200 else (16, 0.85)
    for ax, err, unit, colour in (
        (ax_t, err_trans, "m", "#1f5fbf"),
        (ax_r, err_rot, "rad", "#bf5f1f"),
    ):
        ax.scatter(t2, err, s=size, alpha=alpha, color=colour, linewidths=0)
        if len(err):
            ax.axhline(np.mean(err), color=colour, lw=1, ls="--",
                       label=f"mean {np.mean(err):.4g} {unit} ({len(err)} relations)")  # fmt: skip
        if len(err) >= 20:
            # running median over ~2 % of the relations shows the trend under the scatter
            k = max(5, len(err) // 50)
            e = err[order]
            med = np.array([np.median(e[max(0, i - k) : i + k + 1]) for i in range(0, len(e), k)])
            ax.plot(t2[order][::k], med, color="black", lw=1.2, label="running median")
        if len(err):
            ax.legend(loc="upper left", fontsize=8)
        ax.set_ylim(bottom=0)  # errors are magnitudes: read them from zero
        ax.set_ylabel(f"error [{unit}]")
        ax.grid(alpha=0.3)
    ax_r.set_xlabel("time of the relation's later pose [s]")
    ax_t.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


FLOORPLAN_WALL_RGB = (40, 110, 220)  # blue: the floorplan's walls
MAP_WALL_RGB = (220, 40, 40)  # red: the SLAM map's walls, registered onto the floorplan
BOTH_RGB = (20, 20, 20)  # black: a cell that is a wall in both


def overlay_png(
    path: str | Path | BinaryIO,
    floorplan_walls: np.ndarray,
    map_walls_xy: np.ndarray,
    resolution: float,
    origin: Sequence[float],
    lines: Sequence[str],
    min_width: int = 640,
) -> None:
    """The floorplan's walls (blue) and the map's walls (red; black where both) on the world grid.

    floorplan_walls: `(H, W) bool` world cells, `[iy, ix]` with row 0 at the bottom;
    map_walls_xy: `(K, 2)` [m] the map's wall cell centres already in the world frame.
    """
    h, w = floorplan_walls.shape
    ix = np.floor((map_walls_xy[:, 0] - origin[0]) / resolution).astype(np.int64)
    iy = np.floor((map_walls_xy[:, 1] - origin[1]) / resolution).astype(np.int64)
    inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    map_walls = np.zeros((h, w), dtype=bool)
    map_walls[iy[inside], ix[inside]] = True
    rgb = np.full((h, w, 3), 255, dtype=np.uint8)
    rgb[floorplan_walls] = FLOORPLAN_WALL_RGB
    rgb[map_walls] = MAP_WALL_RGB
    rgb[floorplan_walls & map_walls] = BOTH_RGB
    img = Image.fromarray(np.ascontiguousarray(rgb[::-1]), mode="RGB")  # top row first
    scale = max(1, int(np.ceil(min_width / max(w, 1))))
    if scale > 1:
        img = img.resize((img.width * scale, img.height * scale), Image.Resampling.NEAREST)
    draw = ImageDraw.Draw(img, "RGBA")
    font = _font(max(12, img.width // 50))
    legend = [
        ("floorplan walls", FLOORPLAN_WALL_RGB),
        ("map walls (registered)", MAP_WALL_RGB),
        ("both", BOTH_RGB),
    ]
    rows = [(s, (90, 0, 0)) for s in lines] + legend
    pad = 6
    boxes = [draw.textbbox((0, 0), s, font=font) for s, _ in rows]
    line_h = max(b[3] - b[1] for b in boxes) + 4
    box_w = max(b[2] - b[0] for b in boxes) + 2 * pad + line_h
    draw.rectangle((0, 0, box_w, line_h * len(rows) + 2 * pad), fill=(255, 255, 255, 225))
    for i, (s, colour) in enumerate(rows):
        y = pad + i * line_h
        x = pad
        if i >= len(lines):  # a swatch before each legend entry
            draw.rectangle((x, y + 2, x + line_h - 6, y + line_h - 4), fill=colour)
            x += line_h
        draw.text((x, y), s, fill=(0, 0, 0) if i >= len(lines) else colour, font=font)
    img.save(path, format="PNG")
