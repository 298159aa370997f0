"""Map quality from the floorplan (issue 22): leave-one-building-out cross-validation of the
models against predicting the training mean and a free-area-only model, a predicted-vs-measured
scatter plot, and how long `mapqual predict` takes on a 2000 x 2000 plan.

    python benchmarks/bench_predict.py [BATCH_OUT...] [--worlds DIR ...] [--plot FILE.png]
    python benchmarks/bench_predict.py --speed-only
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.predict.crossval import METHODS, CvResult, leave_one_building_out  # noqa: E402
from worker.predict.dataset import build_datasets, read_runs  # noqa: E402
from worker.predict.fit import feature_source  # noqa: E402

LABELS = {
    "trees": "gradient boosting (median)",
    "linear": "ridge (linear)",
    "mean": "training mean",
    "free_area": "free area alone",
}


def print_cv(cv: CvResult, unit: str) -> None:
    """The methods side by side: Spearman over worlds and buildings, MAE."""
    s = cv.scores()
    print(f"\n{cv.target}: {len(cv.worlds)} worlds, {len(set(cv.buildings))} buildings")
    print(f"  {'method':<28} {'Spearman worlds':>15} {'Spearman bldgs':>15} {'MAE':>12}")
    for m in METHODS:
        r = s[m]
        print(f"  {LABELS[m]:<28} {r['spearman_worlds']:>15.3f} {r['spearman_buildings']:>15.3f}"
              f" {r['mae']:>9.4f} {unit}")  # fmt: skip
    raw = 100 * s["trees"]["interval_coverage"]
    cal = 100 * s["trees"]["calibrated_interval_coverage"]
    print(f"  80 % interval holds the measured value for {cal:.0f} % of the held-out worlds "
          f"(the quantile trees' own 10-90 %: {raw:.0f} %)")  # fmt: skip


def scatter(cvs: list[tuple[CvResult, str]], path: Path) -> None:
    """Predicted (held out) vs measured, both targets, log axes, 80 % intervals as bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(cvs), figsize=(6 * len(cvs), 5.2))
    for ax, (cv, unit) in zip(np.atleast_1d(axes), cvs, strict=True):
        m, p = cv.measured, cv.predicted["trees"]
        furn = np.array(["furniture" in w for w in cv.worlds])
        low, high = cv.calibrated_bounds()  # what `mapqual predict` prints, held out
        err = np.maximum(np.vstack([p - low, high - p]), 0.0)  # median may cross a bound
        for mask, label, marker in ((~furn, "no furniture", "o"), (furn, "furniture", "s")):
            ax.errorbar(m[mask], p[mask], yerr=err[:, mask], fmt=marker, ms=5, alpha=0.8,
                        elinewidth=0.6, capsize=2, label=f"{label} (trees, 80 %)")  # fmt: skip
        ax.scatter(m, cv.predicted["linear"], marker="x", c="grey", s=18, label="ridge")
        lo, hi = min(m.min(), p.min()) * 0.8, max(m.max(), p.max()) * 1.25
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set(xscale="log", yscale="log", xlim=(lo, hi), ylim=(lo, hi),
               xlabel=f"measured mean B error [{unit}]",
               ylabel=f"predicted, building held out [{unit}]")  # fmt: skip
        rho = cv.scores()["trees"]["spearman_worlds"]
        ax.set_title(f"{cv.target}: Spearman {rho:.2f} (leave one building out)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    print(f"\nscatter plot: {path}")


def room_grid_plan(folder: Path, n: int = 2000, room: int = 200) -> Path:
    """A map_server YAML + PNG: n x n pixels at 0.05 m, square rooms with 1 m doors."""
    from PIL import Image

    img = np.full((n, n), 255, np.uint8)
    img[[0, -1], :] = img[:, [0, -1]] = 0
    for k in range(room, n - 1, room):
        img[k, :] = img[:, k] = 0
    for k in range(room, n - 1, room):
        for s in range(0, n - room + 1, room):
            mid = s + room // 2
            img[k, mid - 10 : mid + 10] = img[mid - 10 : mid + 10, k] = 255
    Image.fromarray(img).save(folder / "grid.png")
    (folder / "grid.yaml").write_text(
        "image: grid.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return folder / "grid.yaml"


def speed(repeats: int = 5) -> None:
    """Load + features + prediction on a 2000 x 2000 plan in process (after a warm-up), and
    the whole `mapqual predict` command (interpreter start and imports included)."""
    from worker.predict.model import load_model, predict
    from worker.world.features import features_of
    from worker.world.loader import load_world

    with tempfile.TemporaryDirectory() as tmp:
        plan = room_grid_plan(Path(tmp))
        model = load_model()
        predict(model, features_of(load_world(plan)))  # warm-up (numba cache, imports)
        walls, cpus, feats = [], [], []
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            world = load_world(plan)
            t1 = time.perf_counter()
            predict(model, features_of(world))
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            feats.append(time.perf_counter() - t1)
        cmd = [str(Path(sys.executable).with_name("mapqual")), "predict", str(plan)]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        cli = time.perf_counter() - t0
    print("\n2000 x 2000 plan (100 rooms), median of", repeats)
    print(
        f"  load + features + predict: {np.median(walls):.3f} s wall, "
        f"{np.median(cpus):.3f} s CPU (features + predict alone {np.median(feats):.3f} s wall)"
    )
    print(f"  `mapqual predict` command, interpreter start included: {cli:.2f} s wall")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("batches", nargs="*", type=Path, help="batch output folders (runs.csv)")
    ap.add_argument("--worlds", nargs="+", type=Path, default=[ROOT / "worlds"])
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--plot", type=Path, default=ROOT / "docs" / "predict_scatter.png")
    ap.add_argument("--speed-only", action="store_true")
    args = ap.parse_args()
    if not args.speed_only:
        # by default the whole explorations the bundled model is trained on
        batches = args.batches or sorted((ROOT / "data" / "training").glob("*-full-*/runs.csv"))
        ds = build_datasets(read_runs(batches), feature_source(args.worlds))[args.slam]
        print(f"training data: {', '.join(str(b) for b in batches)}")
        cvs = [(leave_one_building_out(ds, "b_mean_t"), "m"),
               (leave_one_building_out(ds, "b_mean_r"), "rad")]  # fmt: skip
        for cv, unit in cvs:
            print_cv(cv, unit)
        scatter(cvs, args.plot)
    speed()


if __name__ == "__main__":
    main()
