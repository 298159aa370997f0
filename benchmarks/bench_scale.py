"""Real-time factor and peak memory of whole runs against the size of the building (issue 52).

The cost of a simulated second should follow what the robot sees, not the map's bounding box:
this runs the same settings on plans of growing size and prints, for each, the map's cells,
the real-time factor and the peak resident memory, and the ratio of each plan's real-time
factor to the first plan's (issue 52's proof: RTF(virginia_cross) / RTF(office_a) >= 0.7 at
600 s simulated on both cores).

    .venv/bin/python benchmarks/bench_scale.py [--worlds worlds/bormann/office_a.yaml ...]
        [--generate warehouse:120x60 hospital:200x100 ...] [--time-limit 600] [--seed 1]
        [--slam rbpf] [--threads N] [--against OTHER_CHECKOUT] [--plot scale.png]
        [--out rows.jsonl] [--plot-from rows.jsonl ...]

--generate KIND:WxH adds a plan made by `mapqual world generate` (this tree's generator, seed 1)
in a temporary folder; --against runs every plan in OTHER too (its own .venv's interpreter,
the same driver, benchmarks/run_once.py), this tree and the other in turn, plan by plan.
Each run's line gives its components' peak memory too (benchmarks/memory_parts.py).
--out appends each plan's row (both trees' figures) to a JSONL file as it is measured;
--plot-from draws the plot (--plot) and prints the table from such files instead of running,
so that plans measured by several invocations end in one table.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SLAM_DELTA = 0.05  # [m] SlamParams.delta
DEFAULT_WORLDS = ["worlds/bormann/office_a.yaml", "worlds/schools/virginia_cross.yaml"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="*", default=None, help="map_server YAMLs (this tree's)")
    ap.add_argument("--generate", nargs="*", default=[], help="KIND:WxH generated plans")
    ap.add_argument("--time-limit", type=float, default=600.0, help="[s] simulated")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--threads", type=int, default=None, help="slam.threads (default: cores)")
    ap.add_argument("--against", type=Path, help="another checkout, run beside this one")
    ap.add_argument("--plot", type=Path, help="write RTF and peak memory against cells here")
    ap.add_argument("--out", type=Path, help="append each plan's row to this JSONL file")
    ap.add_argument("--plot-from", type=Path, nargs="*", help="rows (JSONL) to table and plot")
    args = ap.parse_args()
    if args.plot_from:
        rows = [json.loads(x) for f in args.plot_from for x in f.read_text().splitlines() if x]
        rows.sort(key=lambda r: r.get("slam_cells", r["cells"]))
        trees = [k for k in ("this", "other") if all(k in r for r in rows)]
        _print(rows, trees)
        if args.plot is not None:
            _plot(rows, trees, args.plot)
        return
    worlds = [ROOT / w for w in (DEFAULT_WORLDS if args.worlds is None else args.worlds)]
    with tempfile.TemporaryDirectory() as tmp:
        worlds += [_generated(spec, Path(tmp)) for spec in args.generate]
        trees = {"this": (Path(sys.executable), ROOT)}
        if args.against is not None:
            other = args.against.resolve()
            if not (other / "worker" / "pipeline.py").is_file():
                ap.error(f"--against: {other} is no mapqual checkout")
            py = other / ".venv" / "bin" / "python"
            trees["other"] = (py if py.exists() else Path(sys.executable), other)
        rows = []
        for w in worlds:
            rows.append(_measure(w, trees, args))
            if args.out is not None:
                with args.out.open("a") as f:
                    f.write(json.dumps(rows[-1]) + "\n")
    _print(rows, list(trees))
    if args.plot is not None:
        _plot(rows, list(trees), args.plot)


def _generated(spec: str, folder: Path) -> Path:
    """Write the plan `KIND:WxH` (seed 1) into folder; its YAML's path."""
    from worker.world.generate import BuildingSpec, generate, write_world

    kind, _, size = spec.partition(":")
    width, _, height = size.partition("x")
    b = BuildingSpec(kind, float(width), float(height), seed=1)  # type: ignore[arg-type]
    return write_world(generate(b), b, folder, f"{kind}_{size}")


def _measure(world: Path, trees: dict, args: argparse.Namespace) -> dict:
    """One run of `world` in each tree (alternating which goes first by the plan's index)."""
    from worker.world.loader import load_world

    facts = load_world(world).facts
    row = {"world": world.stem, "cells": facts.width_px * facts.height_px}
    # the SLAM's map over the plan, at slam.delta (0.05 m): a school drawn at 0.1 m a pixel has
    # four times its plan's cells
    row["slam_cells"] = round(facts.width_m * facts.height_m / SLAM_DELTA**2)
    for name, (py, tree) in trees.items():
        cmd = [
            str(py), str(ROOT / "benchmarks" / "run_once.py"), "--tree", str(tree),
            "--world", str(world.resolve()), "--slam", args.slam, "--seed", str(args.seed),
            "--time-limit", str(args.time_limit),
        ]  # fmt: skip
        if args.threads is not None:
            cmd += ["--threads", str(args.threads)]
        out = subprocess.run(cmd, capture_output=True, text=True, cwd=tree)
        if out.returncode != 0:
            sys.exit(f"{name} ({tree}) failed on {world}:\n{out.stderr[-2000:]}")
        got = json.loads(out.stdout.strip().splitlines()[-1])
        row[name] = {**got, "rtf": got["sim_s"] / got["wall_s"]}
        print(
            f"{time.strftime('%H:%M', time.gmtime())} UTC, load {os.getloadavg()[0]:.1f}: "
            f"{name} {world.stem}: x{row[name]['rtf']:.2f}, {got['peak_mb']:.0f} MiB, "
            f"{got['outcome']}, {got['sim_s']:.0f} s simulated; per component (MiB) "
            + ", ".join(f"{k} {v:.0f}" for k, v in got.get("parts_mb", {}).items()),
            flush=True,
        )
    return row


def _print(rows: list[dict], trees: list[str]) -> None:
    head = f"{'world':<26} {'plan cells':>11} {'SLAM cells':>11}"
    for name in trees:
        head += f" {name + ' RTF':>10} {'peak MiB':>9} {'RTF/first':>9}"
    print(head)
    for row in rows:
        line = f"{row['world']:<26} {row['cells']:>11,} {row.get('slam_cells', 0):>11,}"
        for name in trees:
            rtf, first = row[name]["rtf"], rows[0][name]["rtf"]
            line += f" {rtf:>10.2f} {row[name]['peak_mb']:>9.0f} {rtf / first:>9.3f}"
        print(line)


def _plot(rows: list[dict], trees: list[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.5))
    cells = [r.get("slam_cells", r["cells"]) / 1e6 for r in rows]
    for name in trees:
        a.plot(cells, [r[name]["rtf"] for r in rows], "o-", label=name)
        b.plot(cells, [r[name]["peak_mb"] for r in rows], "o-", label=name)
    x = "SLAM map cells at 0.05 m [millions]"
    a.set(xlabel=x, ylabel="real-time factor", title="Speed")
    b.set(xlabel=x, ylabel="peak resident memory [MiB]", title="Memory")
    b.axhline(1024, color="grey", lw=0.8, ls="--")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)


if __name__ == "__main__":
    main()
