"""The external SLAM protocol's own cost: the odometry algorithm in-process against the same
algorithm through the protocol (its twin, `python -m worker.slam.external.twin odometry`, a
child process), on the same world and seed. The twin asks for GMapping's gate in its ready, as
the example program does, so mapqual sends it only the scans that update its map (about one in
seven in office_a); `--every-scan` makes it take every scan, the cost of a program that must.

Target (issue 20): the protocol costs at most 10 % of a run's time. The protocol's cost is the
time the twin run spends beyond the in-process run's (framing, the pipe round trip of every
step sent, the maps sent, the program's start-up), over the twin run's time: by the whole
run's wall time, by the SLAM calls' wall time, and by CPU (this process and the reaped child).
Both runs must be the same bit for bit (checked). Each round's cost is the twin run's figure
less the in-process run's just before it (the machine's speed drifts within minutes, a pair's
does not); the median of the rounds is judged. Wall time on a busy machine holds the
scheduler's wake-up latency of two processes taking turns (two wake-ups a step); CPU does not.
The last line sets the twin's one-time start-up apart (a fresh Python with numpy and numba's
init, ~0.6 s of CPU: the program's own cost, paid once a run, shrinking with the run's
length). By default a run is a whole run, ended by its stop rules as runs are (the thesis's
2 h limit: office_a seed 1 is explored, no frontier left, at 1022 s; about 3 min a round);
`--time-limit 600` times a 600 s slice of it, where the start-up weighs twice as much.

    .venv/bin/python benchmarks/bench_external.py [--world worlds/bormann/office_a.yaml]
        [--seed 1] [--time-limit 7200] [--repeats 3] [--example] [--split] [--every-scan]

--example also times the plain-Python example (examples/external_slam/), for information;
--split only says where the CPU goes: mapqual's, the SLAM's in it, and the program's own.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TWIN = [sys.executable, "-m", "worker.slam.external.twin", "odometry"]
EXAMPLE = [sys.executable, str(ROOT / "examples/external_slam/dead_reckoning_slam.py")]


def _params(command: list[str] | None, time_limit: float):
    from worker.run_params import RunParams

    data: dict = {"explore": {"time_limit": time_limit}}
    if command is None:
        data["algorithm"] = "odometry"
    else:
        data["algorithm"] = "external"
        data["slam"] = {"external": {"name": "bench", "command": command}}
    return RunParams.from_json(data)


def _cpu_s() -> float:
    """[s] CPU time of this process and of its reaped children."""
    me, kids = (
        resource.getrusage(resource.RUSAGE_SELF),
        resource.getrusage(resource.RUSAGE_CHILDREN),
    )
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _timed(world, params, seed: int):
    """(wall [s], CPU [s], result) of one run."""
    from worker.pipeline import run_one

    t0, c0 = time.perf_counter(), _cpu_s()
    result = run_one(world, params, seed)
    return time.perf_counter() - t0, _cpu_s() - c0, result


def _startup_s(laser) -> tuple[float, float]:
    """[s] (wall, CPU) from nothing to the twin's first answer (spawn, imports, handshake, the
    first scan), then bye: the one-time part of the protocol's cost."""
    from worker.slam.params import SlamParams
    from worker.slam.registry import make_slam

    ext = _params(TWIN, 1.0).slam
    t0, c0 = time.perf_counter(), _cpu_s()
    slam = make_slam("external", laser, SlamParams(external=ext.external))
    slam.process(0.0, np.zeros(3), np.full(laser.n_beams, laser.range_max))
    took = time.perf_counter() - t0
    slam.close()
    return took, _cpu_s() - c0


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default=str(ROOT / "worlds/bormann/office_a.yaml"))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument(
        "--time-limit", type=float, default=7200.0, help="[s] simulated (default: a whole run)"
    )
    ap.add_argument("--repeats", type=int, default=3, help="runs of each, alternated")
    ap.add_argument("--example", action="store_true", help="also time the example program")
    ap.add_argument("--split", action="store_true", help="only: where the CPU goes, per process")
    ap.add_argument(
        "--every-scan", action="store_true",
        help="the twin takes every scan (no gate in its ready): a program that must see them all",
    )  # fmt: skip
    return ap.parse_args()


def main() -> None:
    args = _args()
    if args.every_scan:
        TWIN.append("--every-scan")

    from worker.world.loader import load_world

    world = load_world(args.world)
    if args.split:
        _split(world, args)
        return
    local_p, twin_p = _params(None, args.time_limit), _params(TWIN, args.time_limit)
    _timed(world, _params(None, 5.0), args.seed)  # warm the numba caches
    _timed(world, _params(TWIN, 5.0), args.seed)
    rows: dict[str, list[tuple[float, float, float]]] = {"in-process": [], "twin": []}
    last = {}
    for _ in range(args.repeats):  # alternated, so that a change of load hits both
        for name, params in (("in-process", local_p), ("twin", twin_p)):
            wall, cpu, last[name] = _timed(world, params, args.seed)
            rows[name].append((wall, cpu, last[name].summary.timings.slam_wall_s))
    twin, local = last["twin"].exploration, last["in-process"].exploration
    same = np.array_equal(twin.pose_est, local.pose_est)
    sim_s, steps = last["twin"].summary.timings.sim_time_s, len(twin.t)
    print(
        f"{world.name}, seed {args.seed}, {sim_s:.0f} s simulated ({steps} steps), medians of "
        f"{args.repeats}; the same run bit for bit: {same}; load {os.getloadavg()[0]:.1f}"
    )
    med = {k: tuple(statistics.median(r[i] for r in v) for i in range(3)) for k, v in rows.items()}
    for name, (wall, cpu, slam) in med.items():
        print(
            f"  {name:11s} run {wall:7.2f} s wall, {cpu:7.2f} s CPU, SLAM {slam:6.2f} s wall, "
            f"x{sim_s / wall:.1f} real time"
        )
    # each round's twin run against the in-process run just before it (the machine's speed
    # drifts within minutes; a pair does not): the median of the rounds' costs and shares
    pairs = list(zip(rows["in-process"], rows["twin"], strict=True))
    _report("run wall", [(t[0] - i[0], t[0]) for i, t in pairs], steps)
    _report("SLAM wall", [(t[2] - i[2], t[0]) for i, t in pairs], steps)
    _report("CPU", [(t[1] - i[1], t[1]) for i, t in pairs], steps)
    wall, cpu = _startup_s(local_p.sim.laser)
    once = f"{wall:.2f} s wall, {cpu:.2f} s CPU"
    print(f"  of which once, the twin's start-up and first answer: {once}")
    # what stays when the one-time start-up (Python, numpy, numba's init in a fresh process:
    # the program's own, not the protocol's) is set apart: the per-step part
    _report("CPU per step", [(t[1] - i[1] - cpu, t[1]) for i, t in pairs], steps)
    if args.example:
        _example(world, args)


def _example(world, args) -> None:
    """One line: the example program's run, timed as the others."""
    wall, cpu, result = _timed(world, _params(EXAMPLE, args.time_limit), args.seed)
    s = result.summary
    print(
        f"  example     run {wall:7.2f} s wall, {cpu:7.2f} s CPU, SLAM "
        f"{s.timings.slam_wall_s:6.2f} s wall, {s.outcome} ({s.stop}), "
        f"coverage {100 * s.coverage:.1f} %"
    )


def _split(world, args) -> None:
    """Per run: mapqual's CPU, the SLAM calls' CPU in it, and the program's CPU (read from
    /proc just before it is stopped), in-process and through the twin, alternated."""
    from worker.pipeline import run_one
    from worker.slam.external import client
    from worker.slam.odometry import OdometrySlam

    acc = {"slam": 0.0, "child": 0.0}

    def timed(f):
        def g(*a, **k):
            c = time.process_time()
            try:
                return f(*a, **k)
            finally:
                acc["slam"] += time.process_time() - c

        return g

    def close(self, _close=client.ExternalSlam.close):
        if self.pid is not None:
            st = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
            acc["child"] = (int(st[11]) + int(st[12])) / os.sysconf("SC_CLK_TCK")
        _close(self)

    OdometrySlam.process = timed(OdometrySlam.process)  # type: ignore[method-assign]
    OdometrySlam.occupancy = timed(OdometrySlam.occupancy)  # type: ignore[method-assign]
    client.ExternalSlam.close = close  # type: ignore[method-assign]
    for _ in range(args.repeats):
        for name, command in (("in-process", None), ("twin", TWIN)):
            run_one(world, _params(command, 5.0), args.seed)  # warm
            acc.update(slam=0.0, child=0.0)
            c0, t0 = time.process_time(), time.perf_counter()
            run_one(world, _params(command, args.time_limit), args.seed)
            cpu, wall = time.process_time() - c0, time.perf_counter() - t0
            print(
                f"  {name:11s} {wall:6.2f} s wall; mapqual {cpu:5.2f} s CPU, of which SLAM "
                f"{acc['slam']:5.2f} s; the program {acc['child']:5.2f} s CPU; "
                f"load {os.getloadavg()[0]:.1f}"
            )
    _, cpu = _startup_s(_params(None, 1.0).sim.laser)
    print(f"  the twin's start-up alone: {cpu:.2f} s CPU")


def _report(what: str, costs: list[tuple[float, float]], steps: int) -> None:
    """One line: the protocol's cost by `what` over the rounds, as (cost [s], the twin run's
    total [s]) pairs: the median share, its range, and the verdict on the median."""
    shares = sorted(c / total for c, total in costs)
    cost = statistics.median(c for c, _ in costs)
    share = statistics.median(shares)
    verdict = "met" if share <= 0.10 else "NOT met"
    of = "CPU" if what.startswith("CPU") else "wall time"
    print(
        f"  protocol cost ({what}) {cost:6.2f} s = {100 * share:5.1f} % of the twin run's {of} "
        f"(rounds {100 * shares[0]:.1f}-{100 * shares[-1]:.1f} %; {1000 * cost / steps:.2f} ms a "
        f"step); target <= 10 %: {verdict}"
    )


if __name__ == "__main__":
    main()
