"""The README's picture: a run's SLAM map over its floorplan, with ground truth and estimate.

    python docs/img/front_picture.py RUN_FOLDER WORLD_FILE -o docs/img/office_a_overlay.png

Reads the run's report folder as `mapqual run` writes it (map.pgm + map.yaml, gt.tum,
est.tum; the SLAM's frame is the world's: it starts at the true start pose).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import yaml  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from PIL import Image  # noqa: E402

from worker.world.loader import load_world  # noqa: E402


def draw(run: Path, world_file: Path, out: Path) -> None:
    """Floorplan light grey, the SLAM map's free cells pale blue and walls black, both paths."""
    world = load_world(world_file)
    meta = yaml.safe_load((run / "map.yaml").read_text())
    pgm = np.flipud(np.asarray(Image.open(run / meta["image"])))  # bottom row first
    res, (ox, oy, _) = float(meta["resolution"]), meta["origin"]
    h, w = world.occ.shape
    fig, ax = plt.subplots(figsize=(9, 9 * h / w + 0.6), dpi=110)
    wx, wy = world.origin[0], world.origin[1]
    plan = (wx, wx + w * world.resolution, wy, wy + h * world.resolution)
    ax.imshow(np.where(world.occ, 0.72, 1.0), cmap="gray", vmin=0, vmax=1, origin="lower",
              extent=plan, interpolation="nearest")  # fmt: skip
    layer = np.full(pgm.shape, np.nan)
    layer[pgm >= 250] = 0  # free
    layer[pgm <= 50] = 1  # occupied
    extent = (ox, ox + pgm.shape[1] * res, oy, oy + pgm.shape[0] * res)
    cmap = ListedColormap(["#dbe8f7", "#000000"])
    ax.imshow(layer, cmap=cmap, vmin=0, vmax=1, origin="lower", extent=extent,
              interpolation="nearest")  # fmt: skip
    gt, est = (np.loadtxt(run / name) for name in ("gt.tum", "est.tum"))
    ax.plot(gt[:, 1], gt[:, 2], color="#1a9e1a", lw=2.8, label="ground truth")
    ax.plot(est[:, 1], est[:, 2], color="#d62020", lw=1.2, label="SLAM estimate")
    ax.plot(gt[0, 1], gt[0, 2], "o", color="black", ms=5, label="start")
    ax.plot([], [], "s", color="#000000", label="SLAM map: walls")
    ax.plot([], [], "s", color="#dbe8f7", label="SLAM map: free")
    ax.plot([], [], "s", color="#b8b8b8", label="floorplan walls")
    ax.legend(loc="upper right", fontsize=8, framealpha=0.92)
    ax.set(xlim=plan[:2], ylim=plan[2:], xlabel="x [m]", ylabel="y [m]", aspect="equal")
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("world", type=Path)
    parser.add_argument("-o", "--out", type=Path, required=True)
    args = parser.parse_args()
    draw(args.run, args.world, args.out)


if __name__ == "__main__":
    main()
