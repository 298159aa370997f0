"""Throughput of `mapqual batch`'s local process pool: runs per hour with 1 and 2 workers.

Target (issue 9): 2 workers >= 1.8x the runs per hour of one. The same runs (seeds 1..N of
one world, one algorithm, one time limit) go through the batch core as the command runs them
(spawned workers, run_one, report folders, records), without the database; process start-up
counts. The machine is shared: the load average and the cores the batch actually obtained
(its workers' CPU time over wall time) are printed beside each figure; the best of --repeats
is kept, and the order of the two measurements alternates between repeats.

    .venv/bin/python benchmarks/bench_batch.py [--world worlds/bormann/office_a.yaml]
        [--slam odometry] [--runs 8] [--time-limit 600] [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cpu_children() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _batch(specs, workers: int) -> tuple[float, float, float, list[dict]]:
    """Wall time [s] of the whole batch, CPU time [s] of its worker processes, summed
    simulated time [s], and the records."""
    from worker.batch.local import NullSink, run_local
    from worker.batch.state import BatchDir

    records: list[dict] = []

    def on_event(ev) -> None:
        if ev.kind == "finish":
            records.append(ev.record)

    with tempfile.TemporaryDirectory() as tmp:
        cpu0, t0 = _cpu_children(), time.perf_counter()
        run_local(specs, BatchDir(tmp), workers, NullSink(), on_event)
        wall, cpu = time.perf_counter() - t0, _cpu_children() - cpu0
    sim = sum(r["summary"]["timings"]["sim_time_s"] for r in records if r["summary"])
    return wall, cpu, sim, records


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default=str(ROOT / "worlds/bormann/office_a.yaml"))
    ap.add_argument("--slam", default="odometry", choices=["rbpf", "odometry", "oracle", "graph"])
    ap.add_argument("--runs", type=int, default=8)
    ap.add_argument("--time-limit", type=float, default=600.0, help="[s] simulated, per run")
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()

    from worker.batch.experiment import build_groups, expand
    from worker.pipeline import RunParams, run_one

    over = {"worlds": [args.world], "runs": args.runs, "slam": args.slam}
    params = {"explore": {"time_limit": args.time_limit}}
    specs, worlds = expand(build_groups({}, None, over, params))
    # compile the numba kernels once, so that the workers load them from the cache
    warm = RunParams.from_json({"algorithm": args.slam, "explore": {"time_limit": 5.0}})
    run_one(next(iter(worlds.values())), warm, 1)
    print(
        f"{len(specs)} runs of {Path(args.world).stem}, {args.slam}, time limit "
        f"{args.time_limit:g} s; {os.cpu_count()} cores"
    )
    best: dict[int, float] = {}
    for rep in range(args.repeats):
        for workers in (1, 2) if rep % 2 == 0 else (2, 1):
            load0 = os.getloadavg()
            wall, cpu, sim, records = _batch(specs, workers)
            load1 = os.getloadavg()
            assert len(records) == len(specs), "every run must finish"
            rate = 3600.0 * len(specs) / wall
            best[workers] = max(best.get(workers, 0.0), rate)
            print(
                f"repeat {rep + 1}, {workers} worker(s): {wall:6.1f} s wall, {rate:6.0f} runs/h, "
                f"{sim / wall:5.1f}x real time overall; CPU {cpu / len(specs):5.1f} s a run, "
                f"cores obtained {cpu / wall:4.2f}; load avg before {load0[0]:.2f}, after "
                f"{load1[0]:.2f} (1 min)"
            )
    ratio = best[2] / best[1]
    print(f"best: 1 worker {best[1]:.0f} runs/h, 2 workers {best[2]:.0f} runs/h")
    print(f"speed-up with 2 workers: {ratio:.2f}x (target >= 1.8x)")
    print(
        "(cores obtained = worker CPU time / wall time: below the worker count, other "
        "processes held the cores)"
    )


if __name__ == "__main__":
    main()
