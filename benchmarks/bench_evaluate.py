"""Speed of the relations metric: core rate, evo's RPE on the same pairs, `mapqual evaluate`.

Figures (issue 2): core relations/s on 1,000,000 relations over a 100,000-pose trajectory
(target >= 5 million/s on one core); evo's RPE time for the same relations and the ratio
(target >= 50x); `mapqual evaluate` end to end on a 1,000,000-line relations file (target
<= 3 s). Also the SM and L generators on the 100,000 poses (target: seconds).

The process pins itself to one CPU so that "one core" means one core.

    .venv/bin/python benchmarks/bench_evaluate.py [--poses 100000] [--relations 1000000]
        [--evo-relations N] [--repeat 3]
"""

from __future__ import annotations

import argparse
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
from worker.evaluate.relations import (  # noqa: E402
    LParams,
    Relations,
    SMParams,
    relations_L,
    relations_SM,
)
from worker.evaluate.se2 import relative  # noqa: E402
from worker.evaluate.trajectory import Trajectory  # noqa: E402
from worker.evaluate.trajio import write_carmen, write_relations  # noqa: E402


def building_run(n: int, rng: np.random.Generator) -> tuple[Trajectory, Trajectory]:
    """A robot wandering at 0.3-0.8 m/s inside a 40 m x 30 m building for n samples at 10 Hz
    (ground truth), and an estimate with drifting heading and position noise."""
    t = np.arange(n) * 0.1
    xy = np.empty((n, 2))
    th = np.empty(n)
    x, y, a = 20.0, 15.0, 0.0
    turn = rng.normal(0, 0.15, n)
    speed = rng.uniform(0.3, 0.8, n)
    for k in range(n):  # a few hundred ms for 1e5 samples: setup, not measured
        a += turn[k]
        x += 0.1 * speed[k] * np.cos(a)
        y += 0.1 * speed[k] * np.sin(a)
        if not (0.5 < x < 39.5 and 0.5 < y < 29.5):  # bounce off the outer walls
            a += np.pi
            x, y = min(max(x, 0.5), 39.5), min(max(y, 0.5), 29.5)
        xy[k], th[k] = (x, y), a
    gt = Trajectory(t, np.column_stack([xy, th]))
    drift = np.cumsum(rng.normal(0, 2e-4, n))
    est_xy = xy + rng.normal(0, 0.02, (n, 2)) + np.column_stack([drift, -drift]) * 5
    return gt, Trajectory(t, np.column_stack([est_xy, th + drift]))


def random_relations(gt: Trajectory, m: int, rng: np.random.Generator) -> Relations:
    """m B-style relations between random ground-truth samples (exact timestamps)."""
    i = rng.integers(0, len(gt), m)
    j = rng.integers(0, len(gt), m)
    return Relations(gt.t[i], gt.t[j], relative(gt.poses[i], gt.poses[j]))


def best_of(repeat: int, fn) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def evo_time(gt: Trajectory, est: Trajectory, rel: Relations) -> float:
    """evo's RPE (translation and rotation angle, as our one pass gives both) on poses
    interleaved so that its consecutive pairs (2k, 2k+1) are our relations. evo also
    evaluates the (2k+1, 2k+2) pairs, so its time is scaled by m / (2m - 1). Building evo's
    trajectories and our lookups are not timed."""
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D

    def path(tr: Trajectory) -> PosePath3D:
        p1, _ = tr.poses_at(rel.t1)
        p2, _ = tr.poses_at(rel.t2)
        p = np.empty((2 * len(rel), 3))
        p[0::2], p[1::2] = p1, p2
        mats = np.zeros((p.shape[0], 4, 4))
        c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
        mats[:, 0, 0], mats[:, 0, 1], mats[:, 1, 0], mats[:, 1, 1] = c, -s, s, c
        mats[:, 0, 3], mats[:, 1, 3], mats[:, 2, 2], mats[:, 3, 3] = p[:, 0], p[:, 1], 1, 1
        return PosePath3D(poses_se3=list(mats))

    data = (path(gt), path(est))
    t0 = time.perf_counter()
    kinds = (metrics.PoseRelation.translation_part, metrics.PoseRelation.rotation_angle_rad)
    for relation in kinds:
        rpe = metrics.RPE(relation, delta=1, delta_unit=metrics.Unit.frames, all_pairs=False)
        rpe.process_data(data)
    elapsed = time.perf_counter() - t0
    m = len(rel)
    return elapsed * m / (2 * m - 1)


def evo_figure(gt: Trajectory, est: Trajectory, rel: Relations, core: float, m_evo: int) -> None:
    m = len(rel)
    evo_rel = rel if m_evo >= m else Relations(rel.t1[:m_evo], rel.t2[:m_evo], rel.delta[:m_evo])
    t_evo = evo_time(gt, est, evo_rel)
    t_ours = core * m_evo / m
    print(
        f"evo RPE on the same {m_evo} relations: {t_evo:.2f} s; ours {t_ours * 1e3:.0f} ms; "
        f"ratio {t_evo / t_ours:.0f}x (target >= 50)"
    )


def cli_time(rel_path: Path, est_path: Path, repeat: int, cpus: set[int]) -> list[float]:
    exe = Path(sys.executable).with_name("mapqual")
    cmd = [str(exe), "evaluate", "--relations", str(rel_path), "--est", str(est_path), "--json"]

    def unpin() -> None:  # the one-core pin is for the core figure; the CLI may use any core
        os.sched_setaffinity(0, cpus)

    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True, preexec_fn=unpin)
        times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=100_000)
    ap.add_argument("--relations", type=int, default=1_000_000)
    ap.add_argument(
        "--evo-relations", type=int, default=None, help="default: --relations; 0 skips evo"
    )
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    cpus = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cpus)})
    rng = np.random.default_rng(2026)
    gt, est = building_run(args.poses, rng)
    rel = random_relations(gt, args.relations, rng)
    m = len(rel)
    print(f"trajectory: {len(gt)} poses ({gt.duration / 60:.0f} min at 10 Hz); {m} relations")

    evaluate_relations(rel, est)  # load the compiled kernel
    core = best_of(args.repeat, lambda: evaluate_relations(rel, est))
    print(
        f"core: {m / core / 1e6:.2f} million relations/s ({core * 1e3:.0f} ms, one core, "
        f"best of {args.repeat}; target >= 5)"
    )
    shifted = Relations(rel.t1 + 0.05, rel.t2 + 0.05, rel.delta)  # every lookup interpolates
    core_i = best_of(args.repeat, lambda: evaluate_relations(shifted, est))
    print(f"core, all poses interpolated: {m / core_i / 1e6:.2f} million relations/s")

    m_evo = m if args.evo_relations is None else args.evo_relations
    if m_evo > 0:
        evo_figure(gt, est, rel, core, m_evo)
    else:
        print("evo RPE: skipped (--evo-relations 0)")

    with tempfile.TemporaryDirectory() as tmp:
        rel_path, est_path = Path(tmp) / "relations.txt", Path(tmp) / "est.log"
        write_relations(rel_path, rel)
        write_carmen(est_path, est)
        times = cli_time(rel_path, est_path, args.repeat, cpus)
        print(
            f"mapqual evaluate end to end, {m}-line relations file, {len(est)}-pose estimate: "
            f"best {min(times):.2f} s, runs {', '.join(f'{t:.2f}' for t in times)} s "
            f"(target <= 3)"
        )

    for name, fn in (
        ("SM (dt 2 s, > 5 m)", lambda: relations_SM(gt, SMParams())),
        ("L (0.2 m, 0.5 m)", lambda: relations_L(gt, LParams())),
    ):
        fn()  # compile or load the kernels
        t0 = time.perf_counter()
        out = fn()
        print(f"{name} on {len(gt)} poses: {time.perf_counter() - t0:.2f} s, {len(out)} relations")


if __name__ == "__main__":
    main()
