"""Benchmark of graph SLAM beside rbpf: `mapqual slam` real-time factor, peak memory, B error.

    .venv/bin/python benchmarks/bench_graph.py [--world office_a] [--minutes 30] [--seed 1]
        [--log FILE --gt GT.tum] [--algorithms graph,rbpf] [--relations 2000] [--json]
        [--params FILE]

1. simulates a wander log of --minutes simulated minutes in worlds/bormann/<world>.yaml
   (or takes --log and its ground truth --gt);
2. runs `mapqual slam LOG --algorithm A` in a child process (one numba thread) per algorithm,
   one after the other on the same log, and reports each one's wall and CPU time, real-time
   factor (log time / wall time, and / CPU time: the figure a dedicated core would give), peak
   resident memory (of that child alone, from wait4) and updates;
3. scores each trajectory with the same B relations (random ground-truth pairs as
   `mapqual relations --kind B`, at least --relations of them, one seed for all algorithms)
   and `mapqual evaluate`'s translational / rotational errors.
Figures depend on the machine and its load: the load averages are printed with them. On a
shared machine the CPU-time figures are the fairer ones (wall time then counts the waits for
a core).
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.evaluate.metric import evaluate_relations  # noqa: E402
from worker.evaluate.relations import BParams, relations_B  # noqa: E402
from worker.evaluate.trajio import read_trajectory  # noqa: E402
from worker.sim.run import run_simulation  # noqa: E402
from worker.world import load_world  # noqa: E402


def _load() -> str:
    return "load averages " + " ".join(f"{v:.2f}" for v in os.getloadavg())


def run_cli(log: Path, out: Path, algorithm: str, params: Path | None = None) -> dict:
    """`mapqual slam` in a child: its summary plus wall [s], CPU [s] and peak RSS [MB]."""
    mapqual = Path(sys.executable).with_name("mapqual")
    cmd = [str(mapqual), "slam", str(log), "-o", str(out), "--algorithm", algorithm, "--json"]
    if params is not None:
        cmd += ["--params", str(params)]
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    t0 = time.perf_counter()
    with open(out.with_suffix(".out"), "w+") as fh:
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.PIPE, text=True, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        err = proc.stderr.read() if proc.stderr else ""
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode != 0:
            sys.exit(f"mapqual slam --algorithm {algorithm} failed ({proc.returncode}):\n{err}")
        fh.seek(0)
        summary = json.loads(fh.read())
    return summary | {
        "bench_wall_s": wall,
        "bench_cpu_s": usage.ru_utime + usage.ru_stime,
        "peak_mb": usage.ru_maxrss / 1024,
    }


def b_errors(gt_path: Path, est_path: Path, n_min: int, seed: int) -> dict:
    """Mean / max translational [m] and mean rotational [rad] error on B relations."""
    gt, est = read_trajectory(gt_path), read_trajectory(est_path)
    rel = relations_B(gt, est, np.random.default_rng(seed), BParams(min_relations=n_min))
    err = evaluate_relations(rel, est)
    return {
        "b_n": int(len(err.translation)),
        "b_mean_t": float(np.mean(err.translation)),
        "b_max_t": float(np.max(err.translation)),
        "b_mean_r": float(np.mean(err.rotation)),
    }


def _print(alg: str, r: dict, log_s: float) -> None:
    print(
        f"{alg:>8}: {r['bench_wall_s']:7.1f} s wall, {r['bench_cpu_s']:7.1f} s CPU; real-time "
        f"factor {log_s / r['bench_wall_s']:6.1f}x on wall time, {log_s / r['bench_cpu_s']:6.1f}x "
        f"on CPU time; peak {r['peak_mb']:5.0f} MB; {r['updates']} updates; B: mean "
        f"{r['b_mean_t']:.4f} m (max {r['b_max_t']:.3f} m, {r['b_mean_r']:.4f} rad) over "
        f"{r['b_n']} relations"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="office_a")
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--log", type=Path, help="a CARMEN log instead of simulating one")
    ap.add_argument("--gt", type=Path, help="--log's ground truth (TUM or CARMEN)")
    ap.add_argument("--algorithms", default="graph,rbpf")
    ap.add_argument("--relations", type=int, default=2000, help="at least this many B relations")
    ap.add_argument("--json", action="store_true", help="one JSON line per algorithm")
    ap.add_argument("--params", type=Path, help="SLAM parameters file for mapqual slam --params")
    args = ap.parse_args()
    algorithms = [a for a in args.algorithms.split(",") if a]
    if (args.log is None) != (args.gt is None):
        print("bench_graph: --log and --gt go together", file=sys.stderr)
        sys.exit(2)
    if args.log is not None and not (args.log.is_file() and args.gt.is_file()):
        print(f"bench_graph: no such file {args.log} or {args.gt}", file=sys.stderr)
        sys.exit(2)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        if args.log is None:
            world = load_world(ROOT / "worlds" / "bormann" / f"{args.world}.yaml")
            sim = run_simulation(world, tmp / "sim", seed=args.seed, duration_s=60 * args.minutes)
            log, gt = tmp / "sim" / "sim.log", tmp / "sim" / "gt.tum"
            what = f"world {args.world}, seed {args.seed}: {sim.distance_m:.0f} m driven"
        else:
            log, gt = args.log.resolve(), args.gt.resolve()
            what = f"log {log}"
        stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
        if not args.json:
            print(f"{what}; {stamp}; {_load()}")
        for alg in algorithms:
            r = run_cli(log, tmp / alg, alg, args.params)
            r |= b_errors(gt, tmp / alg / "trajectory.tum", args.relations, args.seed)
            if args.json:
                print(json.dumps({k: v for k, v in r.items() if k != "params"}))
            else:
                _print(alg, r, r["log_duration_s"])
        if not args.json:
            print(f"done {time.strftime('%H:%M UTC', time.gmtime())}; {_load()}")


if __name__ == "__main__":
    main()
