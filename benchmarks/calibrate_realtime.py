"""Calibrate real-time emulation's cost model (worker.slam.realtime) against measured CPU time.

    .venv/bin/python benchmarks/calibrate_realtime.py [--log freiburg-079] [--scans 1500]
        [--particles 10 20 40] [--lskip 0 1]

Runs rbpf (threads 1) over the first scans of a real log (the drifting problem of
bench_reallogs, seed 0) for each particle count and beam skip, times every update's CPU time
(this thread's, so other processes on the machine do not count), and fits by least squares
    update CPU [s] = RBPF_C0 + RBPF_C1 * particles * used beams * (iterations + 1);
the same for the odometry baseline's updates against its beams (the scan decimated 1x, 2x,
4x): ODOM_C0 + ODOM_C1 * beams. Prints each configuration's mean, the fit, and its largest
relative error; the constants go into worker/slam/realtime.py by hand (a calibration is a
decision, not a side effect).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_reallogs import DATA, LOGS  # noqa: E402
from worker.sim.carmen import read_laser_log  # noqa: E402
from worker.sim.drift import DriftParams, drifting_problem, log_slice  # noqa: E402
from worker.sim.laser import LaserSpec  # noqa: E402
from worker.slam.params import SlamParams  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402


def update_cpu(
    problem, algorithm: str, params: SlamParams, laser=None, step: int = 1
) -> list[float]:
    """CPU time [s] of each update of `algorithm` over the problem's scans."""
    laser = problem.laser if laser is None else laser
    slam = make_slam(algorithm, laser, params, np.random.default_rng(0))
    out = []
    for k in range(problem.t.shape[0]):
        c0 = time.thread_time()
        updated = slam.process(problem.t[k], problem.pose_odom[k], problem.ranges[k, ::step])
        if updated:
            out.append(time.thread_time() - c0)
    cpu = np.asarray(out[1:])  # the first maps from nothing: left out
    # an update that compiled a kernel (numba, the first time a code path runs) is no cost of
    # the algorithm: updates over 10x the median are left out (counted in the line printed)
    return list(cpu[cpu <= 10 * np.median(cpu)])


def fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """(c0, c1, largest relative error) of y = c0 + c1 x."""
    a = np.column_stack([np.ones_like(x), x])
    (c0, c1), *_ = np.linalg.lstsq(a, y, rcond=None)
    return float(c0), float(c1), float(np.max(np.abs(c0 + c1 * x - y) / y))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", choices=list(LOGS), default="freiburg-079")
    parser.add_argument("--scans", type=int, default=1500)
    parser.add_argument("--particles", type=int, nargs="+", default=[10, 20, 40])
    parser.add_argument("--lskip", type=int, nargs="+", default=[0, 1])
    args = parser.parse_args()
    log = read_laser_log(DATA / LOGS[args.log])
    log = log_slice(log, 0, min(args.scans, log.t.shape[0]))
    problem, _ = drifting_problem(log, 0, DriftParams())
    b = problem.laser.n_beams
    print(f"{args.log}, {problem.t.shape[0]} scans, {b} beams, "
          f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")  # fmt: skip
    update_cpu(log_slice(problem, 0, 300), "rbpf", SlamParams(particles=4, threads=1))  # compile
    xs, ys = [], []
    for n in args.particles:
        for lskip in args.lskip:
            p = SlamParams(particles=n, lskip=lskip, threads=1)
            cpu = update_cpu(problem, "rbpf", p)
            used = -(-b // (lskip + 1))
            xs.append(n * used * (p.iterations + 1))
            ys.append(float(np.mean(cpu)))
            print(f"rbpf particles {n:>3} lskip {lskip}: {len(cpu)} updates, "
                  f"mean {ys[-1] * 1e3:.2f} ms, work {xs[-1]}")  # fmt: skip
    c0, c1, rel = fit(np.array(xs, float), np.array(ys))
    print(f"RBPF_C0 = {c0:.3e}  RBPF_C1 = {c1:.3e}  (largest relative error {rel:.1%})")
    xs, ys = [], []
    for step in (1, 2, 4):
        spec = LaserSpec(
            n_beams=len(range(0, b, step)),
            angle_min=problem.laser.angle_min,
            angle_increment=problem.laser.angle_increment * step,
            range_max=problem.laser.range_max,
        )
        cpu = update_cpu(problem, "odometry", SlamParams(), spec, step)
        xs.append(spec.n_beams)
        ys.append(float(np.mean(cpu)))
        print(f"odometry beams {spec.n_beams}: {len(cpu)} updates, mean {ys[-1] * 1e3:.3f} ms")
    c0, c1, rel = fit(np.array(xs, float), np.array(ys))
    print(f"ODOM_C0 = {c0:.3e}  ODOM_C1 = {c1:.3e}  (largest relative error {rel:.1%})")


if __name__ == "__main__":
    main()
