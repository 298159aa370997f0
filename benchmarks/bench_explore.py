"""Exploration stack speed (and, with --proof, outcomes) on Bormann floorplans.

Default: the wall time the navigation stack (costmap, frontiers, planning, DWA, safety; not the
simulator nor SLAM) spends per simulated second, on the largest Bormann map (office_g), oracle
SLAM: mean and 95th percentile over the first --seconds of a run, one core.

    .venv/bin/python benchmarks/bench_explore.py [--world office_g] [--seconds 600]
    .venv/bin/python benchmarks/bench_explore.py --against /work/main [--rounds 2]
    .venv/bin/python benchmarks/bench_explore.py --proof [--slam oracle|rbpf] [--png DIR] [--md F]

--proof runs whole explorations, by default of every bundled plan (Bormann with and without
furniture, then the 31 schools), and prints outcome, coverage of the reachable free space,
simulated and wall time for each (--md: also as a Markdown table): the proof the CI keeps a
subset of. --worlds takes names under worlds/bormann or worlds/schools, or YAML paths.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.explore.flat_params import explore_params  # noqa: E402
from worker.explore.loop import explore  # noqa: E402
from worker.sim.params import SimParams  # noqa: E402
from worker.sim.simulator import Simulator  # noqa: E402
from worker.slam import registry  # noqa: E402
from worker.slam.params import SlamParams  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402
from worker.world.loader import load_world  # noqa: E402

WORLDS = ROOT / "worlds"


def proof_worlds() -> list[str]:
    """Every bundled Bormann plan (both variants) and every school plan, by name."""
    return [p.stem for d in ("bormann", "schools") for p in sorted((WORLDS / d).glob("*.yaml"))]


def world_path(name: str) -> Path:
    """A world by name (bundled under worlds/bormann or worlds/schools) or by path."""
    if name.endswith((".yaml", ".yml", ".world")):
        return Path(name)
    for d in ("bormann", "schools"):
        if (p := WORLDS / d / f"{name}.yaml").is_file():
            return p
    print(f"bench_explore: no world {name!r} under {WORLDS}/bormann or /schools", file=sys.stderr)
    raise SystemExit(2)


def run(name: str, slam_name: str, seed: int, time_limit: float, **explore_kw):
    world = load_world(world_path(name))
    rng = np.random.default_rng(seed)
    sim_params = SimParams()
    sim = Simulator(world, sim_params, rng)
    oracle = slam_name == "oracle"
    slam = make_slam("odometry" if oracle else slam_name, sim_params.laser, SlamParams(), rng)
    t0 = time.perf_counter()
    params = explore_params(time_limit=time_limit, **explore_kw)
    result = explore(world, sim, slam, params, oracle=oracle)
    return world, result, time.perf_counter() - t0


def per_sim_second(nav_wall_s: np.ndarray, steps_per_s: int = 10) -> np.ndarray:
    """Navigation wall time [s] summed over each whole simulated second."""
    n = len(nav_wall_s) // steps_per_s * steps_per_s
    return nav_wall_s[:n].reshape(-1, steps_per_s).sum(axis=1)


def warm_up() -> None:
    """Compile the numba kernels outside the measurement."""
    run("Freiburg52_scan", "oracle", 0, 20.0)


def bench(args) -> None:
    warm_up()
    print(f"load average at the start: {os.getloadavg()[0]:.2f}")
    world, result, wall = run(args.world, "oracle", args.seed, args.seconds)
    per_s = per_sim_second(result.nav_wall_s) * 1e3
    cpu_s = per_sim_second(result.nav_cpu_s) * 1e3
    h, w = world.occ.shape
    print(f"world {args.world}: {w} x {h} cells ({w * world.resolution:.0f} x "
          f"{h * world.resolution:.0f} m), oracle SLAM, seed {args.seed}")  # fmt: skip
    print(f"simulated {result.t[-1]:.0f} s ({result.outcome}, {result.reason}), "
          f"coverage {100 * result.coverage:.1f} %, path {result.path_length_m:.0f} m, "
          f"wall {wall:.1f} s")  # fmt: skip
    print(f"navigation stack per simulated second: mean {per_s.mean():.2f} ms, "
          f"p95 {np.percentile(per_s, 95):.2f} ms, max {per_s.max():.2f} ms wall "
          f"(target: mean <= 15 ms on one core)")  # fmt: skip
    print(f"  its CPU time (thread): mean {cpu_s.mean():.2f} ms, "
          f"p95 {np.percentile(cpu_s, 95):.2f} ms; load average {os.getloadavg()[0]:.2f} "
          f"at the end (wall time inflates under load, CPU time less)")  # fmt: skip


def proof(args) -> None:
    worlds = args.worlds.split(",") if args.worlds else proof_worlds()
    for name in worlds:
        world_path(name)  # a bad name fails before the warm-up
    warm_up()
    ok = 0
    rows = []
    for name in worlds:
        world, result, wall = run(name, args.slam, args.seed, args.time_limit)
        good = result.completed and result.coverage >= 0.95 and result.collision is None
        ok += good
        print(f"{name:28s} {result.outcome:10s} {result.reason:14s} "
              f"coverage {100 * result.coverage:5.1f} %  sim {result.t[-1]:6.0f} s  "
              f"path {result.path_length_m:5.0f} m  goals {result.goals_reached:3d} ok "
              f"{result.goals_failed:2d} failed  wall {wall:6.1f} s", flush=True)  # fmt: skip
        if result.outcome != "completed":
            print(f"    {result.stop_detail}", flush=True)
        rows.append(
            f"| {name} | {result.outcome} ({result.reason}) | {100 * result.coverage:.1f} | "
            f"{result.t[-1]:.0f} | {result.path_length_m:.0f} | "
            f"{'none' if result.collision is None else 'yes'} | {'yes' if good else 'no'} |"
        )
        if args.md:
            _write_table(Path(args.md), rows, args)
        if args.png:
            from worker.explore.render import render_run

            Path(args.png).mkdir(parents=True, exist_ok=True)
            render_run(world, result, Path(args.png) / f"{name}_{args.slam}.png")
    print(f"{ok}/{len(worlds)} completed with coverage >= 95 % and no collision ({args.slam})")


def _write_table(path: Path, rows: list[str], args) -> None:
    """The proof so far as a Markdown table (rewritten after every run)."""
    head = (
        f"slam {args.slam}, seed {args.seed}, time limit {args.time_limit:g} s\n\n"
        "| world | outcome (stop) | coverage [%] | simulated [s] | path [m] | collision "
        "| >= 95 % |\n|---|---|---:|---:|---:|---|---|\n"
    )
    path.write_text(head + "\n".join(rows) + "\n")


_MEAN = re.compile(r"navigation stack per simulated second: mean ([0-9.]+) ms")
_CPU = re.compile(r"its CPU time \(thread\): mean ([0-9.]+) ms")


def _timed(tree: Path, args) -> tuple[float, float]:
    """(wall, CPU) ms per simulated second of the timing run of `tree`'s bench_explore.py."""
    cmd = [
        sys.executable, str(tree / "benchmarks" / "bench_explore.py"), "--world", args.world,
        "--seconds", str(args.seconds), "--seed", str(args.seed),
    ]  # fmt: skip
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, cwd=tree).stdout
    print(f"--- {tree}\n{out}", end="", flush=True)
    return float(_MEAN.search(out).group(1)), float(_CPU.search(out).group(1))


def against(args) -> None:
    """The timing of this tree and of --against DIR side by side, --rounds times, the order
    alternating; the ratios this / that of the means."""
    trees = (ROOT, Path(args.against).resolve())
    got: dict[Path, list[tuple[float, float]]] = {t: [] for t in trees}
    for k in range(args.rounds):
        for tree in trees if k % 2 == 0 else trees[::-1]:
            got[tree].append(_timed(tree, args))
    mine, theirs = (np.mean(got[t], axis=0) for t in trees)
    print(f"this tree: wall {mine[0]:.2f} ms, CPU {mine[1]:.2f} ms per simulated second; "
          f"{trees[1]}: wall {theirs[0]:.2f} ms, CPU {theirs[1]:.2f} ms; ratio wall "
          f"{mine[0] / theirs[0]:.2f}, CPU {mine[1] / theirs[1]:.2f} "
          f"({args.rounds} rounds)")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="office_g", help="Bormann world for the timing")
    ap.add_argument("--seconds", type=float, default=600.0, help="simulated seconds timed")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--proof", action="store_true", help="whole explorations, outcomes")
    ap.add_argument("--worlds", default="", help="comma-separated list for --proof")
    ap.add_argument("--slam", default="oracle", choices=registry.names())
    ap.add_argument("--time-limit", type=float, default=3600.0, help="per run in --proof [s]")
    ap.add_argument("--png", default="", help="folder for one PNG per --proof run")
    ap.add_argument("--md", default="", help="Markdown table of the --proof runs to write")
    ap.add_argument("--against", default="", help="another checkout: time both side by side")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of --against")
    args = ap.parse_args()
    if args.proof:
        proof(args)
    elif args.against:
        against(args)
    else:
        bench(args)


if __name__ == "__main__":
    main()
