"""Peak resident memory of a whole run on every bundled plan (issue 52: under 1 GB on each).

Lists the plans under worlds/ (worker.world.catalogue.find_worlds: the Bormann plans and the
schools), sorts them by the cells of the SLAM's map over the plan's extent (its area at
slam.delta, 0.05 m: what the particle maps and the navigation's grids grow with), largest
first, and runs each in a process of its own (benchmarks/run_once.py --cold --report: no
warm-up, as `mapqual run` starts, and the report folder written after the run, as it does),
appending one JSON line per plan to --out. Plans already in --out are
skipped, so an interrupted invocation resumes where it stopped.

    .venv/bin/python benchmarks/bench_plans.py --out plans.jsonl [--largest N]
        [--time-limit S] [--slam rbpf] [--seed 1] [--threads N] [--list]
        [--exclude worlds/schools/virginia_cross.yaml ...] [--shard K/N] [--command]

--command runs the command users run instead, `mapqual run PLAN -o DIR` (database, report and
all), each in a fresh folder of its own (its SQLite database there), and reads its peak from the
kernel's account of the finished process (wait4's ru_maxrss), so nothing samples it; the line
then holds sim_s, wall_s, outcome, stop, coverage and peak_mb, without the parts.

--shard K/N runs every N-th plan from the K-th, so that N invocations (one a core, each with
its own --out) share the list; the memory a run holds does not depend on the load.
--time-limit left out: each run's own limit (explore.time_limit, 7,200 s simulated), i.e.
whole runs; on a 2-core machine the 63 plans take most of a day. --list prints the plans and
their cells without running anything. Each line holds the run_once.py figures (sim_s, wall_s,
outcome, coverage, peak_mb, parts_mb, trace) plus the plan's name, its cells at its own
resolution and at the SLAM's, the UTC time, the load and the commit.
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
SLAM_DELTA = 0.05  # [m] SlamParams.delta: the map cells the figures are set against


def plans(folder: Path) -> list[dict]:
    """Every bundled plan with its cells, largest SLAM map first."""
    from worker.world.catalogue import find_worlds
    from worker.world.loader import load_world

    out = []
    for path in find_worlds(folder):
        facts = load_world(path).facts
        out.append({
            "world": str(path.relative_to(ROOT)),
            "plan_cells": facts.width_px * facts.height_px,
            "slam_cells": round(facts.width_m * facts.height_m / SLAM_DELTA**2),
            "area_m2": round(facts.width_m * facts.height_m, 1),
        })  # fmt: skip
    return sorted(out, key=lambda p: (-p["slam_cells"], p["world"]))


def _done(path: Path) -> set[str]:
    if not path.exists():
        return set()
    lines = path.read_text().splitlines()
    return {json.loads(line)["world"] for line in lines if line.strip()}


def _commit() -> str:
    out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                         cwd=ROOT)  # fmt: skip
    return out.stdout.strip()


def _run(plan: dict, args: argparse.Namespace) -> dict:
    cmd = [
        sys.executable, str(ROOT / "benchmarks" / "run_once.py"), "--tree", str(ROOT),
        "--world", plan["world"], "--slam", args.slam, "--seed", str(args.seed), "--cold",
        "--report",
    ]  # fmt: skip
    if args.time_limit is not None:
        cmd += ["--time-limit", str(args.time_limit)]
    if args.threads is not None:
        cmd += ["--threads", str(args.threads)]
    started = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    out = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    if out.returncode != 0:
        return {**plan, "error": out.stderr[-1500:], "utc": started}
    got = json.loads(out.stdout.strip().splitlines()[-1])
    return {**plan, **got, "utc": started, "load": round(os.getloadavg()[0], 1),
            "commit": _commit(), "time_limit": args.time_limit}  # fmt: skip


def _run_command(plan: dict, args: argparse.Namespace) -> dict:
    """`mapqual run` itself, in a fresh folder; its peak from wait4 once it has ended."""
    started = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    with tempfile.TemporaryDirectory(prefix="bench_plans_") as tmp:
        cmd = [
            str(Path(sys.executable).with_name("mapqual")), "run", str(ROOT / plan["world"]),
            "-o", f"{tmp}/report", "--seed", str(args.seed), "--slam", args.slam,
        ]  # fmt: skip
        if args.time_limit is not None:
            cmd += ["--time-limit", str(args.time_limit)]
        env = dict(os.environ)
        if args.threads is not None:
            env["MAPQUAL_SLAM_THREADS"] = str(args.threads)
        t0 = time.perf_counter()
        with open(f"{tmp}/stderr", "wb") as err:
            proc = subprocess.Popen(cmd, cwd=tmp, env=env, stdout=subprocess.DEVNULL, stderr=err)
            _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            tail = Path(f"{tmp}/stderr").read_text(errors="replace")[-1500:]
            return {**plan, "error": tail, "utc": started, "how": "mapqual run"}
        s = json.loads(Path(f"{tmp}/report/summary.json").read_text())
    return {**plan, "how": "mapqual run", "sim_s": s["timings"]["sim_time_s"], "wall_s": wall,
            "outcome": s["outcome"], "stop": s["stop"], "coverage": s["coverage"],
            "peak_mb": usage.ru_maxrss / 1024, "utc": started,
            "load": round(os.getloadavg()[0], 1), "commit": _commit(),
            "time_limit": args.time_limit}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("plans.jsonl"), help="JSONL, appended")
    ap.add_argument("--folder", type=Path, default=ROOT / "worlds")
    ap.add_argument("--largest", type=int, default=None, help="only the N largest plans")
    ap.add_argument("--time-limit", type=float, default=None, help="[s] simulated")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=None, help="slam.threads")
    ap.add_argument("--list", action="store_true", help="print the plans and stop")
    ap.add_argument("--exclude", nargs="*", default=[], help="plans to leave out (paths)")
    ap.add_argument("--shard", default="0/1", help="K/N: every N-th plan from the K-th (0-based)")
    ap.add_argument("--command", action="store_true", help="measure `mapqual run` itself")
    args = ap.parse_args()
    k, n = (int(v) for v in args.shard.split("/"))
    todo = [p for p in plans(args.folder)[: args.largest] if p["world"] not in args.exclude]
    todo = todo[k::n]
    if args.list:
        for p in todo:
            print(f"{p['world']:<50} {p['plan_cells']:>11,} {p['slam_cells']:>11,}")
        return
    done = _done(args.out)
    for plan in todo:
        if plan["world"] in done:
            continue
        row = (_run_command if args.command else _run)(plan, args)
        with args.out.open("a") as f:
            f.write(json.dumps(row) + "\n")
        print(
            f"{row['utc']} UTC: {plan['world']} ({plan['slam_cells']:,} cells): "
            + (f"{row['peak_mb']:.0f} MiB, {row['outcome']}, {row['sim_s']:.0f} s simulated"
               if "error" not in row else "FAILED"),
            flush=True,
        )  # fmt: skip


if __name__ == "__main__":
    main()
