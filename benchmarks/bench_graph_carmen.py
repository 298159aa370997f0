"""Graph SLAM beside rbpf on the real CARMEN logs, with odometry made to drift (a stand-in
until the real-data helper's generator is merged): B error and CPU time per log.

    .venv/bin/python benchmarks/bench_graph_carmen.py [--logs DIR] [--algorithms graph,rbpf]
        [--scale 0.05] [--seed 1] [--relations 1000] [--only aces,csail]

Each log's FLASER poses (the corrected trajectory) are the reference. The odometry is made
from their increments in the robot frame: each component scaled by (1 + f), one factor f per
axis per run drawn uniformly in +-scale / 2 (Stage's model), plus Gaussian noise per step of
0.02 m/m (x, y) and 0.01 rad/rad + 0.005 rad/m (theta), integrated from the first pose; seeded.
Logs whose timestamps do not increase get a clock of one second per scan. Both algorithms run
in this process on one core with their default settings, and are scored on the same B
relations (at least --relations random reference pairs).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.evaluate.metric import evaluate_relations  # noqa: E402
from worker.evaluate.relations import BParams, relations_B  # noqa: E402
from worker.evaluate.se2 import compose, relative  # noqa: E402
from worker.evaluate.trajectory import Trajectory  # noqa: E402
from worker.sim.carmen import read_laser_log  # noqa: E402
from worker.slam.run import run_slam  # noqa: E402

DEFAULT_LOGS = ROOT.parent / "shared" / "data" / "carmen"


def drifting_odometry(ref: np.ndarray, scale: float, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) odometry integrated from the reference poses' increments with per-axis scale
    errors and per-step noise (see the module docstring)."""
    steps = relative(ref[:-1], ref[1:])
    factors = rng.uniform(-0.5 * scale, 0.5 * scale, size=3)
    trans = np.hypot(steps[:, 0], steps[:, 1])
    noisy = steps * (1.0 + factors)
    noisy[:, :2] += rng.normal(size=(len(steps), 2)) * (0.02 * trans)[:, None]
    noisy[:, 2] += rng.normal(size=len(steps)) * (0.01 * np.abs(steps[:, 2]) + 0.005 * trans)
    odom = np.empty_like(ref)
    odom[0] = ref[0]
    for k in range(len(steps)):
        odom[k + 1] = compose(odom[k], noisy[k])
    return odom


def bench_log(path: Path, algorithms: list[str], args: argparse.Namespace) -> None:
    """Run each algorithm on one log and print its B error and CPU time."""
    log = read_laser_log(path)
    t = log.t if np.all(np.diff(log.t) > 0) else np.arange(len(log.t), dtype=np.float64)
    ref = log.pose_odom
    odom = drifting_odometry(ref, args.scale, np.random.default_rng(args.seed))
    gt = Trajectory.from_samples(t, ref)
    drift = np.hypot(*(odom[-1, :2] - ref[-1, :2]))
    print(
        f"{path.name}: {len(t)} scans of {log.laser.n_beams} beams; odometry ends {drift:.2f} m off"
    )
    for alg in algorithms:
        c0 = time.process_time()
        res = run_slam(t, odom, log.ranges, log.laser, alg, rng=np.random.default_rng(args.seed))
        cpu = time.process_time() - c0
        rel = relations_B(
            gt, res.trajectory, np.random.default_rng(args.seed),
            BParams(min_relations=args.relations),
        )  # fmt: skip
        err = evaluate_relations(rel, res.trajectory)
        print(
            f"  {alg:>8}: B mean {np.mean(err.translation):.3f} m (std "
            f"{np.std(err.translation):.3f}, max {np.max(err.translation):.2f}) "
            f"{np.mean(err.rotation):.4f} rad over {len(err.translation)} relations; "
            f"{res.updates} updates, {cpu:.1f} s CPU"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", type=Path, default=DEFAULT_LOGS)
    ap.add_argument("--algorithms", default="graph,rbpf")
    ap.add_argument("--scale", type=float, default=0.05, help="per-axis scale error span")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--relations", type=int, default=1000)
    ap.add_argument("--only", default="", help="comma-separated log name prefixes")
    args = ap.parse_args()
    logs = sorted(args.logs.glob("*.log*"))
    if args.only:
        logs = [p for p in logs if any(p.name.startswith(o) for o in args.only.split(","))]
    if not logs:
        print(f"bench_graph_carmen: no CARMEN logs under {args.logs}", file=sys.stderr)
        sys.exit(2)
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"{stamp}; scale {args.scale}, seed {args.seed}")
    for path in logs:
        bench_log(path, [a for a in args.algorithms.split(",") if a], args)


if __name__ == "__main__":
    main()
