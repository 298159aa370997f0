"""Real-time factor of a whole run (simulate, explore with SLAM, evaluate, write the report) on
office_a with the thesis settings, the share of wall time per stage, the process's peak
resident memory and the peak memory of each component (particle maps, costmap, planners,
simulator, recording: their arrays' nbytes at their largest, sampled every simulated second
through the progress callback, which `mapqual run` passes too; the report: tracemalloc's peak
while its files are written; see benchmarks/memory_parts.py).

Target (issue 6): >= 20x real time on one core. Memory (issue 21): a run under 1 GB; the
largest plans are the ones to check (`--world worlds/bormann/office_g.yaml`).

    .venv/bin/python benchmarks/bench_run.py [--world worlds/bormann/office_a.yaml]
        [--slam rbpf] [--seed 1] [--time-limit 7200] [--slam-threads 1]

--slam-threads 2 gives the scan matcher both cores (slam.threads; the run is the same bit for
bit): the figure a single run reaches on a 2-core machine, beside the one-core target.

Side by side (issue 21: this machine's speed drifts by a third within an hour, so the figure
is a ratio of runs timed alternately, the order swapped every round):

    .venv/bin/python benchmarks/bench_run.py --against OTHER_CHECKOUT [--rounds 3]
        [--this-threads N] [--other-threads N] [--time-limit S] [--this-slam JSON]

times a whole run in this checkout and in OTHER (its own .venv's interpreter) with the same
driver (benchmarks/run_once.py) and prints each round's real-time factors and their ratio,
then the median. --this-threads defaults to the cores `mapqual run` gives a lone run
(worker.slam.threads), --other-threads to the other tree's default; give both 1 for the
one-core comparison. --this-slam '{"coarse_skip": 0}' runs this tree with those SLAM settings
(against itself: a setting's own speed-up, side by side). --this-realtime SPEED runs this
tree's runs under real-time SLAM emulation (issue 51: updates take simulated time, scans
meanwhile dropped).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from memory_parts import PARTS, peak_sampler, traced_peak

from worker.slam import registry

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = _parser()
    args = ap.parse_args()
    if args.this_slam is not None and not isinstance(args.this_slam, dict):
        ap.error("--this-slam must be a JSON object")
    if args.slam_threads < 1:
        ap.error("--slam-threads must be >= 1")
    if args.against is not None:
        if not (args.against / "worker" / "pipeline.py").is_file():
            ap.error(f"--against: {args.against} is no mapqual checkout")
        _side_by_side(args)
        return

    from worker.pipeline import run_one
    from worker.report.folder import SIM_LOG, write_report
    from worker.run_params import RunParams
    from worker.world.loader import load_world

    world = load_world(args.world)
    data = {"algorithm": args.slam, "slam": {"threads": args.slam_threads}}
    if args.time_limit is not None:
        data["explore"] = {"time_limit": args.time_limit}
    params = RunParams.from_json(data)
    # warm the numba caches so that the figures are about running, not compiling
    run_one(world, RunParams.from_json({**data, "explore": {"time_limit": 5.0}}), args.seed)
    sampler, parts = peak_sampler()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        result = run_one(world, params, args.seed, sampler, sim_log=Path(tmp) / SIM_LOG)
        t1 = time.perf_counter()
        write_report(result, tmp)
        t2 = time.perf_counter()
        # written a second time, traced (tracemalloc slows it), for its memory only
        _, parts["report"] = traced_peak(lambda: write_report(result, Path(tmp) / "traced"))
    _print_run(world.name, args, result, (t0, t1, t2), parts)


def _print_run(name: str, args: argparse.Namespace, result, times, parts) -> None:
    """One run's real-time factors, peak memory (whole and per component) and stage shares."""
    t0, t1, t2 = times
    s = result.summary
    t = s.timings
    total = t2 - t0
    nav, slam, sim = t.navigation_wall_s, t.slam_wall_s, t.simulation_wall_s
    other = t.explore_wall_s - nav - slam - sim
    print(
        f"{name}, seed {args.seed}, {args.slam}, {args.slam_threads} scan-matching "
        f"thread(s): {s.outcome}"
        f"{' (' + s.reason + ')' if s.reason else ''}, coverage {s.coverage:.1%}, "
        f"{t.sim_time_s:.0f} s simulated"
    )
    print(f"real-time factor, run_one:            {t.sim_time_s / (t1 - t0):7.1f}x")
    target = "  (target >= 20x on one core)" if args.slam_threads == 1 else ""
    print(f"real-time factor, with report files:  {t.sim_time_s / total:7.1f}x{target}")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # kB on Linux
    print(f"peak resident memory:                 {peak:7.0f} MiB  (target under 1 GB)")
    print("peak memory per component (arrays' nbytes; report: tracemalloc's peak):")
    for name in (*PARTS, "report"):
        print(f"  {name:26s} {parts[name] / 2**20:8.1f} MiB")
    print("share of wall time per stage:")
    for name, v in (
        ("simulation + CARMEN log", sim),
        ("SLAM", slam),
        ("navigation", nav),
        ("exploration loop, other", other),
        ("evaluation", t.evaluate_wall_s),
        ("report files", t2 - t1),
    ):
        print(f"  {name:26s} {v:8.2f} s  {100 * v / total:5.1f} %")


def _parser() -> argparse.ArgumentParser:
    """The command line's options."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default=str(ROOT / "worlds/bormann/office_a.yaml"))
    ap.add_argument("--slam", default="rbpf", choices=registry.names())
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=None, help="[s] simulated")
    ap.add_argument("--slam-threads", type=int, default=1, help="scan-matching threads")
    ap.add_argument("--against", type=Path, help="another checkout to time side by side")
    ap.add_argument("--rounds", type=int, default=3, help="--against: alternations")
    ap.add_argument("--this-threads", type=int, default=None, help="--against: this tree's")
    ap.add_argument("--other-threads", type=int, default=None, help="--against: the other's")
    ap.add_argument(
        "--this-slam",
        type=json.loads,
        default=None,
        help="--against: SLAM settings of this tree's runs, JSON (e.g. '{\"coarse_skip\": 1}')",
    )
    ap.add_argument(
        "--this-realtime",
        type=float,
        default=None,
        metavar="SPEED",
        help="--against: this tree's runs under real-time SLAM emulation at SPEED",
    )
    ap.add_argument(
        "--other-realtime",
        type=float,
        default=None,
        metavar="SPEED",
        help="--against: the other tree's runs under real-time emulation at SPEED",
    )
    return ap


def _side_by_side(args: argparse.Namespace) -> None:
    """Whole runs here and in args.against, alternately; the ratio of real-time factors."""
    from worker.slam.threads import cores

    other = args.against.resolve()
    python = other / ".venv" / "bin" / "python"
    trees = {
        "this": (Path(sys.executable), ROOT, args.this_threads or cores(), args.this_slam),
        "other": (
            python if python.exists() else Path(sys.executable),
            other,
            args.other_threads,
            None,
        ),
    }
    world = Path(args.world)  # the same plan, found under each tree
    if world.is_absolute():
        world = world.resolve().relative_to(ROOT)
    print(f"side by side: this = {ROOT}, other = {other}; {args.slam}, seed {args.seed}, {world}")
    if args.this_slam:
        print(f"this tree's runs with slam settings {json.dumps(args.this_slam)}")
    for name in ("this", "other"):
        if getattr(args, f"{name}_realtime") is not None:
            speed = getattr(args, f"{name}_realtime")
            print(f"{name} tree's runs under real-time SLAM emulation, speed {speed}")
    ratios = []
    for r in range(args.rounds):
        order = list(trees) if r % 2 == 0 else list(reversed(trees))
        got = {}
        for name in order:
            py, tree, threads, slam = trees[name]
            cmd = [
                str(py), str(ROOT / "benchmarks" / "run_once.py"), "--tree", str(tree),
                "--world", str(world), "--slam", args.slam, "--seed", str(args.seed),
            ]  # fmt: skip
            if args.time_limit is not None:
                cmd += ["--time-limit", str(args.time_limit)]
            if threads is not None:
                cmd += ["--threads", str(threads)]
            if slam:
                cmd += ["--slam-params", json.dumps(slam)]
            if getattr(args, f"{name}_realtime") is not None:
                cmd += ["--realtime", str(getattr(args, f"{name}_realtime"))]
            out = subprocess.run(cmd, capture_output=True, text=True, cwd=tree)
            if out.returncode != 0:
                sys.exit(f"{name} ({tree}) failed ({out.returncode}):\n{out.stderr[-2000:]}")
            got[name] = json.loads(out.stdout.strip().splitlines()[-1])
        rtf = {k: v["sim_s"] / v["wall_s"] for k, v in got.items()}
        ratios.append(rtf["this"] / rtf["other"])
        print(
            f"round {r + 1} ({order[0]} first, {time.strftime('%H:%M', time.gmtime())} UTC, load "
            f"{os.getloadavg()[0]:.1f}): this x{rtf['this']:.1f} ({got['this']['threads']} "
            f"thread(s), {got['this']['outcome']}, {got['this']['sim_s']:.0f} s), other "
            f"x{rtf['other']:.1f} ({got['other']['threads']}, {got['other']['outcome']}, "
            f"{got['other']['sim_s']:.0f} s); this / other {ratios[-1]:.3f}; peak memory "
            f"{got['this']['peak_mb']:.0f} / {got['other']['peak_mb']:.0f} MiB"
        )
        print("  per component, MiB this / other: " + _parts_line(got))
    print(f"median real-time factor ratio this / other over {len(ratios)} rounds: "
          f"{statistics.median(ratios):.3f}")  # fmt: skip


def _parts_line(got: dict) -> str:
    """'particle maps 180.5 / 190.1, costmap ...' from two run_once results."""
    this, other = got["this"].get("parts_mb", {}), got["other"].get("parts_mb", {})
    return ", ".join(f"{k} {this[k]:.1f} / {other.get(k, float('nan')):.1f}" for k in this)


if __name__ == "__main__":
    main()
