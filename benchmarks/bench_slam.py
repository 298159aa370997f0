"""Benchmark of the SLAM stage: ms per rbpf update, peak memory, `mapqual slam` real-time factor.

    .venv/bin/python benchmarks/bench_slam.py [--world office_a] [--minutes 30] [--particles 40]
        [--updates 200] [--repeats 2] [--skip-cli] [--log FILE] [--json]
        [--against OTHER_CHECKOUT [--rounds 3]]

1. simulates a wander log of --minutes simulated minutes in worlds/bormann/<world>.yaml;
2. times every filter update of rbpf (541 beams) in this process, on one core, over the
   first --updates updates (numba compiled beforehand, not timed): wall and CPU time, the
   best of --repeats passes (a fresh filter each, same seed, so the same updates);
3. runs `mapqual slam LOG` in a child process (one numba thread) over the whole log and
   reports its wall and CPU time, real-time factor (simulated time / wall time; and / CPU
   time, the figure a dedicated core would give) and peak resident memory.
Figures depend on the machine and its load: the load averages are printed with them. On a
shared machine the CPU-time figures are the fairer ones (wall time then counts the waits for
a core), though they too are inflated by the other processes' use of the caches.

A virtual machine's speed can also drift by a third within an hour, so a change is judged
side by side: --against DIR times the update in this checkout and in another one (a git
worktree of the reference commit, with a .venv or run with this interpreter; its
bench_slam.py must know --log and --json), alternately, --rounds times, on the same log, and
prints each pair and the median ratio.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.sim.carmen import read_laser_log  # noqa: E402
from worker.sim.run import run_simulation  # noqa: E402
from worker.slam.params import SlamParams  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402
from worker.world import load_world  # noqa: E402


def _load() -> str:
    return "load averages " + " ".join(f"{v:.2f}" for v in os.getloadavg())


def _time_updates(log, particles: int, n_updates: int) -> tuple[np.ndarray, np.ndarray]:
    """(wall, CPU) time [s] of each rbpf update over the log's first n_updates updates."""
    warm = make_slam("rbpf", log.laser, SlamParams(particles=2), np.random.default_rng(0))
    for k in range(0, min(400, len(log.t)), 10):  # compile the kernels
        warm.process(log.t[k], log.pose_odom[k], log.ranges[k])
    slam = make_slam("rbpf", log.laser, SlamParams(particles=particles), np.random.default_rng(1))
    wall, cpu = [], []
    for k in range(len(log.t)):
        t0, c0 = time.perf_counter(), time.process_time()
        updated = slam.process(log.t[k], log.pose_odom[k], log.ranges[k])
        dt, dc = time.perf_counter() - t0, time.process_time() - c0
        if updated and slam.updates > 1:  # the first update only registers the scan
            wall.append(dt)
            cpu.append(dc)
            if len(wall) >= n_updates:
                break
    return np.array(wall), np.array(cpu)


def _best_pass(log, args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray]:
    """(wall, CPU) per update of the pass, out of --repeats, with the lowest CPU mean."""
    passes = [_time_updates(log, args.particles, args.updates) for _ in range(args.repeats)]
    return min(passes, key=lambda wc: wc[1].mean())


def _print_updates(log, args: argparse.Namespace, wall: np.ndarray, cpu: np.ndarray) -> None:
    print(
        f"rbpf update, {args.particles} particles, {log.laser.n_beams} beams, one core, over "
        f"{len(wall)} updates (best of {args.repeats} passes): wall mean "
        f"{1000 * wall.mean():.1f} ms, median {1000 * np.median(wall):.1f} ms, "
        f"p95 {1000 * np.percentile(wall, 95):.1f} ms; CPU "
        f"mean {1000 * cpu.mean():.1f} ms, median {1000 * np.median(cpu):.1f} ms "
        f"(target <= 40 ms); {_load()}"
    )


def _side_by_side(log_path: Path, other: Path, args: argparse.Namespace) -> None:
    """Time the update here and in checkout `other`, alternately, on the same log."""
    other_py = other / ".venv" / "bin" / "python"
    if not other_py.exists():
        other_py = Path(sys.executable)
    trees = {"this": (Path(sys.executable), ROOT), "other": (other_py, other)}
    print(f"side by side: this = {ROOT}, other = {other}; {_load()}")
    ratios = []
    for r in range(args.rounds):
        means = {}
        for name, (python, tree) in trees.items():
            cmd = [
                str(python), str(tree / "benchmarks" / "bench_slam.py"), "--log", str(log_path),
                "--skip-cli", "--json", "--particles", str(args.particles),
                "--updates", str(args.updates), "--repeats", str(args.repeats),
            ]  # fmt: skip
            out = subprocess.run(cmd, capture_output=True, text=True, cwd=tree)
            if out.returncode != 0:
                sys.exit(f"{name} ({tree}) failed ({out.returncode}):\n{out.stderr[-2000:]}")
            means[name] = json.loads(out.stdout.strip().splitlines()[-1])["cpu_mean_ms"]
        ratios.append(means["this"] / means["other"])
        print(
            f"round {r + 1}: this {means['this']:.1f} ms, other {means['other']:.1f} ms CPU mean "
            f"per update; this / other = {ratios[-1]:.3f}"
        )
    print(f"median this / other over {len(ratios)} rounds: {np.median(ratios):.3f}; {_load()}")


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="office_a")
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--particles", type=int, default=40)
    ap.add_argument("--updates", type=int, default=200, help="updates timed in process")
    ap.add_argument("--repeats", type=int, default=2, help="timed passes; the best is shown")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-cli", action="store_true", help="skip the whole-log CLI run")
    ap.add_argument("--log", type=Path, help="time on this CARMEN log instead of simulating one")
    ap.add_argument("--json", action="store_true", help="only the update figures, one JSON line")
    ap.add_argument("--against", type=Path, help="another checkout to time side by side")
    ap.add_argument("--rounds", type=int, default=3, help="--against: alternations")
    return ap.parse_args()


def main() -> None:
    args = _args()
    if args.against is not None and not (args.against / "benchmarks" / "bench_slam.py").exists():
        print(
            f"bench_slam: --against: no benchmarks/bench_slam.py under {args.against}",
            file=sys.stderr,
        )
        sys.exit(2)

    if args.log is not None:
        if not args.log.is_file():
            print(f"bench_slam: no log file {args.log}", file=sys.stderr)
            sys.exit(2)
        if args.against is not None:
            _side_by_side(args.log.resolve(), args.against.resolve(), args)
            return
        log = read_laser_log(args.log)
        wall, cpu = _best_pass(log, args)
        if args.json:
            print(json.dumps({"updates": len(wall), "cpu_mean_ms": 1000 * cpu.mean()}))
        else:
            _print_updates(log, args, wall, cpu)
        return

    world = load_world(ROOT / "worlds" / "bormann" / f"{args.world}.yaml")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sim = run_simulation(world, tmp / "sim", seed=args.seed, duration_s=60 * args.minutes)
        if args.against is not None:
            _side_by_side(tmp / "sim" / "sim.log", args.against.resolve(), args)
            return
        log = read_laser_log(tmp / "sim" / "sim.log")
        print(
            f"world {args.world}: {world.width_m:.1f} x {world.height_m:.1f} m; log "
            f"{sim.sim_time_s:.0f} s simulated, {sim.distance_m:.0f} m driven, "
            f"{len(log.t)} scans of {log.laser.n_beams} beams"
        )
        print(_load())
        _print_updates(log, args, *_best_pass(log, args))
        if args.skip_cli:
            return
        _whole_log_cli(tmp, args, sim.sim_time_s)


def _whole_log_cli(tmp: Path, args: argparse.Namespace, sim_time_s: float) -> None:
    """`mapqual slam` over the whole log in a child process: wall, CPU and peak memory."""
    mapqual = Path(sys.executable).with_name("mapqual")
    cmd = [
        str(mapqual),
        "slam",
        str(tmp / "sim" / "sim.log"),
        "-o",
        str(tmp / "slam"),
        "--particles",
        str(args.particles),
        "--json",
    ]
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if out.returncode != 0:
        sys.exit(f"mapqual slam failed ({out.returncode}):\n{out.stderr}")
    wall = time.perf_counter() - t0
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu_s = usage.ru_utime + usage.ru_stime
    peak_mb = usage.ru_maxrss / 1024
    summary = json.loads(out.stdout)
    print(
        f"mapqual slam over the whole log: {wall:.1f} s wall, {cpu_s:.1f} s CPU (the "
        f"process "
        f"spent {summary['wall_s']:.1f} s wall in SLAM, the rest reading the log, starting "
        f"and writing), {summary['updates']} updates; real-time factor "
        f"{sim_time_s / wall:.1f}x on wall time, {sim_time_s / cpu_s:.1f}x on CPU "
        f"time (target >= 20x); peak memory {peak_mb:.0f} MB (target <= 1024 MB); {_load()}"
    )


if __name__ == "__main__":
    main()
