"""Third-party SLAM beside ours: rbpf, graph and MRPT's programs on the same logs, paired.

    .venv/bin/python benchmarks/bench_third_party.py [--algorithms rbpf graph mrpt_rbpf mrpt_icp]
        [--seeds 0 1 2] [--scans 800] [--plans office_a lab_c_scan ...] [--sim-time 60]
        [--out results.jsonl] [--table-only]

Two sets of logs, every algorithm replaying the same one (offline, `worker.slam.run`):
- the three bundled real logs (bench_reallogs' drifting problem: real scans, odometry
  drifting by a seeded 3 % scale error; ground truth = the corrected poses), first --scans;
- simulated runs of Bormann plans: a run driven on the ground truth (the oracle, so the
  log does not depend on any algorithm under test) for --sim-time simulated seconds records a
  CARMEN log with the simulator's noisy odometry and TRUEPOS; every algorithm replays it.
Score: the mean translational error over B relations (>= 500 random pairs of ground-truth
poses, the relations' seed the log's), of each algorithm's final trajectory. Each (log, seed)
row is appended to --out as it finishes (so a long batch can be stopped and resumed: rows
already there are skipped). The table: mean per log, then each algorithm's paired difference
against rbpf over every (log, seed) with a 95 % t interval, beside Kuemmerle et al. (2009)'s
published RBPF figures for the real buildings.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy import stats

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_reallogs import DATA, LOGS, b_errors  # noqa: E402
from worker.evaluate.trajectory import Trajectory  # noqa: E402
from worker.sim.carmen import read_laser_log  # noqa: E402
from worker.sim.drift import DriftParams, drifting_problem, log_slice  # noqa: E402
from worker.slam.run import run_slam  # noqa: E402

PUBLISHED_RBPF_M = {"aces": 0.060, "csail": 0.049, "freiburg-079": 0.061}
PLANS = ["office_a", "office_b", "office_d", "lab_a_scan", "lab_c_scan", "Freiburg52_scan"]


def real_problem(name: str, seed: int, scans: int):
    log = read_laser_log(DATA / LOGS[name])
    if scans:
        log = log_slice(log, 0, min(scans, log.t.shape[0]))
    return drifting_problem(log, seed, DriftParams())


def sim_problem(plan: str, seed: int, sim_time: float):
    """The log of an oracle-driven run of `plan` and its ground truth at the scans."""
    from worker.pipeline import run_one
    from worker.run_params import RunParams
    from worker.world.loader import load_world

    world = load_world(ROOT / "worlds" / "bormann" / f"{plan}.yaml")
    params = RunParams.from_json({"algorithm": "oracle", "explore": {"time_limit": sim_time}})
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "sim.log"
        run_one(world, params, seed, sim_log=path)
        log = read_laser_log(path)
    gt = Trajectory.from_samples(log.t_gt, log.pose_gt)
    return log, gt


def run_row(kind: str, name: str, seed: int, args) -> dict:
    problem, gt = (real_problem(name, seed, args.scans) if kind == "real"
                   else sim_problem(name, seed, args.sim_time))  # fmt: skip
    row = {"kind": kind, "log": name, "seed": seed, "scans": int(problem.t.shape[0])}
    for algorithm in args.algorithms:
        t0 = time.perf_counter()
        try:
            result = run_slam(problem.t, problem.pose_odom, problem.ranges, problem.laser,
                              algorithm, None, np.random.default_rng(seed))  # fmt: skip
        except Exception as exc:  # a program that fails is a result too: said in the row
            row[algorithm] = {"error": str(exc).splitlines()[0][:200]}
            continue
        trans, rot, n = b_errors(gt, result.trajectory, seed)
        row[algorithm] = {"trans_m": trans, "rot_rad": rot, "relations": n,
                          "wall_s": time.perf_counter() - t0}  # fmt: skip
    return row


def paired(rows: list[dict], a: str, ref: str = "rbpf") -> tuple[float, float, float, int]:
    """(mean of a - ref, 95 % interval low, high, pairs) over the rows both scored."""
    d = np.array([r[a]["trans_m"] - r[ref]["trans_m"] for r in rows
                  if "trans_m" in r.get(a, {}) and "trans_m" in r.get(ref, {})])  # fmt: skip
    if d.size < 2:
        return float(d.mean()) if d.size else float("nan"), float("nan"), float("nan"), d.size
    half = stats.t.ppf(0.975, d.size - 1) * d.std(ddof=1) / np.sqrt(d.size)
    return float(d.mean()), float(d.mean() - half), float(d.mean() + half), int(d.size)


def table(rows: list[dict], algorithms: list[str]) -> str:
    logs = sorted({(r["kind"], r["log"]) for r in rows})
    out = ["| log | seeds | " + " | ".join(algorithms) + " | published RBPF |",
           "|---|---|" + "---|" * (len(algorithms) + 1)]  # fmt: skip
    for kind, name in logs:
        sel = [r for r in rows if r["log"] == name]
        cells = []
        for a in algorithms:
            v = [r[a]["trans_m"] for r in sel if "trans_m" in r.get(a, {})]
            cells.append(f"{np.mean(v):.3f}" if v else "failed")
        pub = PUBLISHED_RBPF_M.get(name)
        out.append(f"| {name} ({kind}) | {len(sel)} | " + " | ".join(cells)
                   + f" | {'' if pub is None else f'{pub:.3f}'} |")  # fmt: skip
    out += ["", "| algorithm - rbpf | set | mean [m] | 95 % interval [m] | pairs |",
            "|---|---|---|---|---|"]  # fmt: skip
    for a in algorithms:
        if a == "rbpf":
            continue
        for label, kinds in (("real", {"real"}), ("simulated", {"sim"}), ("all", {"real", "sim"})):
            m, lo, hi, n = paired([r for r in rows if r["kind"] in kinds], a)
            if n:
                out.append(f"| {a} | {label} | {m:+.3f} | [{lo:+.3f}, {hi:+.3f}] | {n} |")
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--algorithms", nargs="+",
                        default=["rbpf", "graph", "mrpt_rbpf", "mrpt_icp", "odometry"])  # fmt: skip
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--logs", nargs="*", choices=list(LOGS), default=list(LOGS))
    parser.add_argument("--scans", type=int, default=800, help="real logs: first N scans (0 all)")
    parser.add_argument("--plans", nargs="*", default=PLANS)
    parser.add_argument("--sim-time", type=float, default=60.0, help="[s] each simulated run")
    parser.add_argument("--out", type=Path, default=Path("third_party.jsonl"))
    parser.add_argument("--table-only", action="store_true")
    parser.add_argument("--mrpt-timeout-per-scan", type=float, default=None, metavar="S",
                        help="MRPT wall-time limit per scan (a loaded machine)")  # fmt: skip
    args = parser.parse_args()
    if args.mrpt_timeout_per_scan is not None:
        from worker.slam.mrpt import slam as mrpt_slam

        mrpt_slam.TIMEOUT_PER_SCAN_S = args.mrpt_timeout_per_scan
    done = [json.loads(x) for x in args.out.read_text().splitlines()] if args.out.exists() else []
    have = {(r["kind"], r["log"], r["seed"]) for r in done}
    jobs = [("real", n, s) for s in args.seeds for n in args.logs]
    jobs += [("sim", p, s) for s in args.seeds for p in args.plans]
    for kind, name, seed in jobs:
        if args.table_only or (kind, name, seed) in have:
            continue
        row = run_row(kind, name, seed, args)
        with args.out.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
        done.append(row)
        print(f"{kind} {name} seed {seed}: " + ", ".join(
            f"{a} {row[a].get('trans_m', float('nan')):.3f}" for a in args.algorithms
        ), file=sys.stderr, flush=True)  # fmt: skip
    print(f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load averages "
          + " ".join(f"{v:.2f}" for v in os.getloadavg()))  # fmt: skip
    print(table(done, args.algorithms))


if __name__ == "__main__":
    main()
