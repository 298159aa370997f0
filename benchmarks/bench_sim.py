"""Simulator speed: ray-caster scans per second on the largest Bormann map, and the real-time
factor of `mapqual simulate --drive wander` over 30 simulated minutes, log writing included.

Run: .venv/bin/python benchmarks/bench_sim.py [--world worlds/bormann/office_a.yaml]
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.sim.laser import LaserSpec  # noqa: E402
from worker.world import load_world  # noqa: E402
from worker.world.raycast import cast_scans, cast_scans_skip, jump_map  # noqa: E402


def best_rate(fn, n_scans: int, repeats: int = 3) -> tuple[float, float]:
    """(scans per CPU second, scans per wall second), best of `repeats`. CPU time is the
    steadier figure on a shared machine."""
    best_cpu = best_wall = float("inf")
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        best_cpu = min(best_cpu, time.process_time() - c0)
        best_wall = min(best_wall, time.perf_counter() - t0)
    return n_scans / best_cpu, n_scans / best_wall


def bench_raycast(world_path: Path, n: int) -> None:
    world = load_world(world_path)
    laser = LaserSpec()
    angles = laser.angles
    rng = np.random.default_rng(0)
    free = np.argwhere(world.clearance > 0.3)
    pick = free[rng.choice(len(free), n)]
    res = world.resolution
    ox, oy = world.origin
    poses_random = np.column_stack(
        [ox + (pick[:, 1] + 0.5) * res, oy + (pick[:, 0] + 0.5) * res, rng.uniform(-3, 3, n)]
    )
    # Poses along a wandering path: what the simulator actually asks for.
    from worker.sim.drivers import Wanderer
    from worker.sim.params import SimParams
    from worker.sim.simulator import Simulator

    sim = Simulator(world, SimParams(), np.random.default_rng(1))
    wanderer = Wanderer(laser, np.random.default_rng(2))
    path = []
    for _ in range(n):
        path.append(sim.pose_gt)
        sim.step(*wanderer.command(sim.scan(), 0.1))
    poses_path = np.array(path)
    jump = jump_map(world.occ, world.clearance, res)
    occ = world.occ
    rmax = laser.range_max
    cast_scans(occ, res, ox, oy, poses_random[:2], angles, rmax)  # compile / load the cache
    cast_scans_skip(jump, res, ox, oy, poses_random[:2], angles, rmax)
    h, w = occ.shape
    print(
        f"ray caster on {world.name} ({w} x {h} cells), {laser.n_beams} beams, one core, per CPU s:"
    )
    for label, poses in (("random free poses", poses_random), ("along a wander path", poses_path)):
        plain = best_rate(lambda p=poses: cast_scans(occ, res, ox, oy, p, angles, rmax), n)
        skip = best_rate(lambda p=poses: cast_scans_skip(jump, res, ox, oy, p, angles, rmax), n)
        print(
            f"  {label:<20}: cast_scan {plain[0]:6.0f} scans/s (wall {plain[1]:6.0f})   "
            f"cast_scan_skip {skip[0]:6.0f} scans/s (wall {skip[1]:6.0f})"
        )


def bench_simulate(world_path: Path, duration: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            str(ROOT / ".venv" / "bin" / "mapqual"),
            "simulate",
            str(world_path),
            "--drive",
            "wander",
            "--duration",
            str(duration),
            "--seed",
            "1",
            "-o",
            tmp,
        ]
        warm = cmd[:3] + ["--duration", "5", "-o", tmp]
        subprocess.run(warm, check=True, capture_output=True)  # warm the numba cache
        cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        done = subprocess.run(cmd, check=True, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
        size_mb = (Path(tmp) / "sim.log").stat().st_size / 1e6
    print(f"mapqual simulate {world_path.name} --drive wander --duration {duration:.0f}:")
    print(f"  {done.stdout.splitlines()[0]}")
    print(
        f"  whole command (process start, world load, run, {size_mb:.0f} MB log): {wall:.2f} s "
        f"wall, {cpu:.2f} s CPU -> real-time factor {duration / wall:.0f}x wall, "
        f"{duration / cpu:.0f}x CPU"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--raycast-world", type=Path, default=ROOT / "worlds/bormann/office_g.yaml")
    ap.add_argument("--world", type=Path, default=ROOT / "worlds/bormann/office_a.yaml")
    ap.add_argument("--scans", type=int, default=3000)
    ap.add_argument("--duration", type=float, default=1800.0)
    args = ap.parse_args()
    bench_raycast(args.raycast_world, args.scans)
    bench_simulate(args.world, args.duration)


if __name__ == "__main__":
    main()
