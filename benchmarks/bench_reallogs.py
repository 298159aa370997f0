"""Benchmark on real laser data: rbpf against dead reckoning on the three corrected Radish logs.

    .venv/bin/python benchmarks/bench_reallogs.py [--logs aces csail freiburg-079] [--seed 0]
        [--scans N] [--particles 40] [--algorithms rbpf odometry] [--json] [--proposal]

For each log of ../shared/data/carmen/ (README there): the SLAM problem of
`worker.sim.drift.drifting_problem` (its real scans, odometry drifting by a 3 % scale error
per axis and 5 % per-step noise, seeded; ground truth = the corrected poses), run through
rbpf (GMapping's defaults, the thesis's 40 particles) and through the odometry baseline, and
scored with B relations (random pairs of ground-truth poses; at least 500 of them, so that
the mean does not swing with the draw; the relations' seed is the problem's). Prints one row a
log: mean translational [m] and rotational [rad] B error of each (rbpf's final trajectory,
along its best particle's path, and beside it its online estimate, each scan's when it was
processed), rbpf / odometry (final), wall time, and the figures Kuemmerle et al. (2009)
publish for RBPF on these buildings (their relations, with the robots' real odometry:
comparable in kind, not in value).
--proposal runs rbpf with its sampled improved proposal (off by default: SampledProposal).
--scans N takes the first N scans only (the test's slices). Runs one log at a time (the
machine is shared); the whole of Freiburg 079 (4,791 scans) takes minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.shared_data import CARMEN  # noqa: E402
from worker.evaluate.metric import evaluate_relations  # noqa: E402
from worker.evaluate.relations import BParams, relations_B  # noqa: E402
from worker.evaluate.trajectory import Trajectory  # noqa: E402
from worker.sim.carmen import read_laser_log  # noqa: E402
from worker.sim.drift import DriftParams, drifting_problem, log_slice  # noqa: E402
from worker.slam.params import SampledProposal, SlamParams  # noqa: E402
from worker.slam.run import run_slam  # noqa: E402

DATA = CARMEN  # ../shared/data/carmen beside the checkout (or MAPQUAL_SHARED)
LOGS = {
    "aces": "aces-corrected.log.gz",
    "csail": "csail-corrected.log.gz",
    "freiburg-079": "freiburg-079-corrected.log.gz",
}
# Kuemmerle et al. (2009), Table 1 as the data README quotes it: RBPF, mean translational error
PUBLISHED_RBPF_M = {
    "aces": "0.060 +/- 0.049",
    "csail": "0.049 +/- 0.049",
    "freiburg-079": "0.061 +/- 0.044",
}
B_PARAMS = BParams(min_relations=500)


def b_errors(gt: Trajectory, est: Trajectory, seed: int) -> tuple[float, float, int]:
    """(mean translational [m], mean rotational [rad], relations) of B relations."""
    rel = relations_B(gt, est, np.random.default_rng(seed), B_PARAMS)
    err = evaluate_relations(rel, est, B_PARAMS.max_gap)
    ok = err.evaluated
    return float(err.translation[ok].mean()), float(err.rotation[ok].mean()), int(ok.sum())


def run_log(name: str, args: argparse.Namespace) -> dict:
    """The problem of one log, each algorithm run and scored."""
    log = read_laser_log(DATA / LOGS[name])
    if args.scans:
        log = log_slice(log, 0, min(args.scans, log.t.shape[0]))
    problem, gt = drifting_problem(log, args.seed, DriftParams())
    row: dict = {"log": name, "scans": int(log.t.shape[0])}
    for algorithm in args.algorithms:
        params = SlamParams(
            particles=args.particles,
            proposal=SampledProposal() if args.proposal else None,
        )
        t0 = time.perf_counter()
        result = run_slam(
            problem.t,
            problem.pose_odom,
            problem.ranges,
            problem.laser,
            algorithm,
            params,
            np.random.default_rng(args.seed),
        )
        wall = time.perf_counter() - t0
        trans, rot, n = b_errors(gt, result.trajectory, args.seed)
        row[algorithm] = {"trans_m": trans, "rot_rad": rot, "relations": n, "wall_s": wall}
        if result.online is not result.trajectory:
            trans, rot, _ = b_errors(gt, result.online, args.seed)
            row[algorithm].update(online_trans_m=trans, online_rot_rad=rot)
    return row


def _print(rows: list[dict], args: argparse.Namespace) -> None:
    print(
        f"B relations (>= {B_PARAMS.min_relations}), seed {args.seed}, {args.particles} particles,"
        f" {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, load averages "
        + " ".join(f"{v:.2f}" for v in os.getloadavg())
    )
    head = f"{'log':<13} {'scans':>5}"
    for a in args.algorithms:
        head += f" {a + ' t [m]':>14} {a + ' r [rad]':>15} {a + ' s':>10}"
    if "rbpf" in args.algorithms:
        head += f" {'online t [m]':>12} {'online r':>9}"
    if {"rbpf", "odometry"} <= set(args.algorithms):
        head += f" {'rbpf/odom t':>11} {'rbpf/odom r':>11}"
    print(head + "  published RBPF t [m]")
    for row in rows:
        line = f"{row['log']:<13} {row['scans']:>5}"
        for a in args.algorithms:
            r = row[a]
            line += f" {r['trans_m']:>14.3f} {r['rot_rad']:>15.4f} {r['wall_s']:>10.1f}"
        if "rbpf" in args.algorithms:
            r = row["rbpf"]
            line += f" {r['online_trans_m']:>12.3f} {r['online_rot_rad']:>9.4f}"
        if {"rbpf", "odometry"} <= set(args.algorithms):
            t = row["rbpf"]["trans_m"] / row["odometry"]["trans_m"]
            r = row["rbpf"]["rot_rad"] / row["odometry"]["rot_rad"]
            line += f" {t:>11.3f} {r:>11.3f}"
        print(line + f"  {PUBLISHED_RBPF_M[row['log']]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--logs", nargs="+", choices=list(LOGS), default=list(LOGS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--scans", type=int, default=0, help="first N scans only (0: all)")
    parser.add_argument("--particles", type=int, default=40)
    parser.add_argument(
        "--algorithms", nargs="+", choices=["rbpf", "odometry"], default=["rbpf", "odometry"]
    )
    parser.add_argument("--json", action="store_true", help="print the rows as JSON too")
    parser.add_argument(
        "--proposal", action="store_true", help="rbpf with the sampled proposal (SampledProposal)"
    )
    args = parser.parse_args()
    rows = []
    for name in args.logs:
        rows.append(run_log(name, args))
        print(f"{name}: done", file=sys.stderr, flush=True)
    _print(rows, args)
    if args.json:
        print(json.dumps(rows))


if __name__ == "__main__":
    main()
