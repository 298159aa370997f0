"""Graph SLAM beside rbpf on the real CARMEN logs with drifting odometry: B error and CPU time.

    .venv/bin/python benchmarks/bench_graph_carmen.py [--logs aces csail freiburg-079]
        [--algorithms graph rbpf] [--seed 0] [--scans N] [--particles 40] [--out DIR]
        [--params FILE]

The problem of each log is `worker.sim.drift.drifting_problem` with its default DriftParams
(3 % scale error per axis, 5 % per-step noise, seeded), exactly as benchmarks/bench_reallogs.py
makes it, so graph and rbpf solve the same problems as rbpf's real-log benchmark. Both run
in this process on one core, rbpf with the thesis's 40 particles, graph with its defaults, and
are scored as bench_reallogs scores (`b_errors`: B relations, at least 500 random
ground-truth pairs, more when the pilot sample of the estimate asks for more; the relations'
seed is the problem's). Each is scored on the trajectory `mapqual slam` writes
(run_slam's: graph's final optimised one, after its offline final optimisation, whose CPU
time is printed apart and included in the run's; rbpf's along its best particle); the online
estimate is printed beside it. --out DIR writes each run's trajectory (TUM), the
graph's loop closures and a PNG of its map with the closures drawn, to look at a bad run.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_reallogs import DATA, LOGS, b_errors  # noqa: E402
from worker.evaluate.trajectory import Trajectory  # noqa: E402
from worker.param_io import from_dict, load_params_file  # noqa: E402
from worker.sim.carmen import read_laser_log  # noqa: E402
from worker.sim.drift import DriftParams, drifting_problem, log_slice  # noqa: E402
from worker.slam.params import SlamParams, with_defaults_for  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402


def bench_log(name: str, args: argparse.Namespace) -> dict[str, float]:
    """Run each algorithm on one log's problem; print and return its mean B error [m]."""
    log = read_laser_log(DATA / LOGS[name])
    if args.scans:
        log = log_slice(log, 0, min(args.scans, log.t.shape[0]))
    problem, gt = drifting_problem(log, args.seed, DriftParams())
    drift = np.hypot(*(problem.pose_odom[-1, :2] - log.pose_odom[-1, :2]))
    print(f"{name}: {len(problem.t)} scans; odometry ends {drift:.2f} m off", flush=True)
    out: dict[str, float] = {}
    for alg in args.algorithms:
        c0 = time.process_time()
        slam, est = _run(problem, alg, args)
        online = Trajectory.from_samples(problem.t, est)
        final = getattr(slam, "final_trajectory", None)
        # what run_slam (mapqual slam) gives: the final trajectory where there is one
        c1 = time.process_time()
        traj = online if final is None else Trajectory.from_samples(problem.t, final())
        cpu_final = time.process_time() - c1
        cpu = time.process_time() - c0
        trans, rot, n = b_errors(gt, traj, args.seed)
        out[alg] = trans
        extra = ""
        if final is not None:  # graph, and rbpf along its best particle
            extra = f"; online estimate {b_errors(gt, online, args.seed)[0]:.3f} m"
        if alg == "graph":
            extra += (
                f"; {slam.nodes.n} nodes, {len(slam.closures)} closures, "
                f"{slam.ambiguous_closures} ambiguous, {slam.rejected_closures} rejected, "
                f"{slam.reverse_rejected_closures} refused by the reverse match, "
                f"{slam.weak_far_closures} too weak for their correction, "
                f"{slam.opposed_closures} onto a wall's other face, "
                f"{slam.match_failures} match failures, {slam.gated_matches} gated; "
                f"final optimisation "
                f"{cpu_final:.1f} s CPU, {slam.final_matched} nodes matched again"
            )
        print(
            f"  {alg:>8}: B mean {trans:.3f} m {rot:.4f} rad over {n} relations; "
            f"{cpu:.1f} s CPU{extra}",
            flush=True,
        )
        if args.out:
            _write(args.out / name, alg, slam, traj, gt)
    return out


def _run(problem, alg: str, args: argparse.Namespace):
    """(the SLAM object after the log, (N, 3) its online estimate at every scan)."""
    given = {"particles": args.particles}
    if args.params is not None:  # as mapqual slam --params reads it
        data = load_params_file(args.params)
        given |= data["slam"] if isinstance(data.get("slam"), dict) else data
    params = with_defaults_for(from_dict(SlamParams, given, "slam"), alg)
    slam = make_slam(alg, problem.laser, params, np.random.default_rng(args.seed))
    est = np.empty((problem.t.shape[0], 3))
    for k in range(problem.t.shape[0]):
        slam.process(problem.t[k], problem.pose_odom[k], problem.ranges[k])
        est[k] = slam.pose_estimate()
    return slam, est


def _write(out: Path, alg: str, slam, traj: Trajectory, gt: Trajectory) -> None:
    """The run's trajectory (TUM), and its map with the reference, the estimate and (graph)
    the loop closures drawn, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / f"{alg}.tum", np.column_stack([traj.t, traj.poses]), fmt="%.6f")
    grid = slam.occupancy()
    h, w = grid.shape
    x0, y0 = grid.origin
    ext = (x0, x0 + w * grid.resolution, y0, y0 + h * grid.resolution)
    fig, ax = plt.subplots(figsize=(10, 10), dpi=100)
    ax.imshow(grid.to_image()[::-1], cmap="gray", origin="lower", extent=ext)
    ax.plot(gt.poses[:, 0], gt.poses[:, 1], "g-", lw=0.7, label="reference")
    ax.plot(traj.poses[:, 0], traj.poses[:, 1], "b-", lw=0.7, label=alg)
    for c in getattr(slam, "closures", []):
        a, b = slam.nodes.poses[c.candidate], slam.nodes.poses[c.node]
        ax.plot([a[0], b[0]], [a[1], b[1]], "r-", lw=1.0)
    ax.set_aspect("equal")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / f"{alg}.png")
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--logs", nargs="+", choices=list(LOGS), default=list(LOGS))
    ap.add_argument(
        "--algorithms", nargs="+", choices=["graph", "rbpf", "odometry"], default=["graph", "rbpf"]
    )
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--scans", type=int, default=0, help="first N scans only (0: all)")
    ap.add_argument("--particles", type=int, default=40)
    ap.add_argument("--out", type=Path, default=None, help="write trajectories and maps here")
    ap.add_argument("--params", type=Path, default=None, help="SLAM parameters (YAML / JSON)")
    args = ap.parse_args()
    load = " ".join(f"{v:.2f}" for v in os.getloadavg())
    stamp = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"{stamp}; load averages {load}; seed {args.seed}; drift {DriftParams()}")
    rows = {name: bench_log(name, args) for name in args.logs}
    if {"graph", "rbpf"} <= set(args.algorithms):
        for name, r in rows.items():
            print(f"{name}: graph / rbpf {r['graph'] / r['rbpf']:.3f}")


if __name__ == "__main__":
    main()
