"""One whole run in the checkout it is started in, for `bench_run.py --against`: prints one
JSON line {sim_s, wall_s, cpu_s, outcome, threads, peak_mb, parts_mb, stop, coverage, ate,
trace} (peak_mb: the process's peak resident memory in MiB during the measured run, see below;
parts_mb: each
component's peak, MiB, as benchmarks/memory_parts.py measures it, through a progress callback
given to both trees; stop, coverage, ate: the summary's, None where a tree has none; trace:
[t, coverage, resident MiB, particle maps MiB, planners MiB] every 60 s simulated).
Uses only what every checkout since 39ad88e has (load_world, RunParams.from_json, run_one),
so the same driver times both trees:

    OTHER/.venv/bin/python THIS/benchmarks/run_once.py --tree OTHER [--world W] [--slam rbpf]
        [--seed 1] [--time-limit S] [--threads N] [--slam-params JSON] [--explore JSON]

--threads N sets slam.threads (left out: the tree's own default). The numba caches are warmed
by a 5 s run first; the report files are not written (the same in both trees). After the
warm-up the C heap's free memory is given back (glibc's malloc_trim) and the peak is reset
(/proc/self/clear_refs), so peak_mb is the run's own, not what the warm-up left in the
allocator's free lists (about 270 MiB on the generated 200 m x 100 m warehouse). --cold: no
warm-up (a fresh process, as `mapqual run`; the first run loads the kernels from numba's cache).
--report then writes the run's report folder (worker.report.folder.write_report) into a
temporary folder before the peak is read, as `mapqual run` does after the run: its figures
hold a plan-sized image for a moment, so without it the peak is the run's alone.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import sys
import tempfile
import time
from pathlib import Path

from memory_parts import peak_mb, peak_sampler


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, required=True, help="the checkout whose code runs")
    ap.add_argument("--world", default="worlds/bormann/office_a.yaml", help="under --tree")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=None, help="[s] simulated")
    ap.add_argument("--threads", type=int, default=None, help="slam.threads")
    ap.add_argument("--slam-params", type=json.loads, default={}, help="more slam settings, JSON")
    ap.add_argument("--realtime", type=float, default=None, help="real-time SLAM at this speed")
    ap.add_argument("--cold", action="store_true", help="no warm-up run")
    ap.add_argument("--explore", type=json.loads, default={}, help="explore settings, JSON")
    ap.add_argument("--report", action="store_true", help="write the report folder too")
    args = ap.parse_args()
    sys.path.insert(0, str(args.tree.resolve()))
    from worker.pipeline import run_one
    from worker.world.loader import load_world

    try:
        from worker.run_params import RunParams
    except ImportError:  # older trees kept it in the pipeline
        from worker.pipeline import RunParams

    data: dict = {"algorithm": args.slam}
    slam = dict(args.slam_params)
    if args.threads is not None:
        slam["threads"] = args.threads
    if slam:  # no section at all otherwise, as older trees expect
        data["slam"] = slam
    world = load_world(args.tree / args.world)
    if not args.cold:
        run_one(world, RunParams.from_json({**data, "explore": {"time_limit": 5.0}}), args.seed)
        _fresh_peak()
    explore = dict(args.explore)
    if args.time_limit is not None:
        explore["time_limit"] = args.time_limit
    if explore:
        data["explore"] = explore
    if args.realtime is not None:  # issue 51's option (absent from older trees)
        data["realtime"] = {"speed": args.realtime}
    params = RunParams.from_json(data)
    trace: list = []
    sampler, parts = peak_sampler(trace)
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_one(world, params, args.seed, sampler)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    if args.report:
        from worker.report.folder import write_report

        with tempfile.TemporaryDirectory() as folder:
            write_report(result, folder)
    s = result.summary
    s = s if isinstance(s, dict) else s.to_dict()  # a dict in older trees
    print(json.dumps({
        "sim_s": s["timings"]["sim_time_s"], "wall_s": wall, "cpu_s": cpu,
        "outcome": s["outcome"], "threads": params.slam.threads,
        "peak_mb": peak_mb(),
        "parts_mb": {k: round(v / 2**20, 1) for k, v in parts.items()},
        "stop": s.get("stop"), "coverage": s.get("coverage"), "ate": s.get("ate"), "trace": trace,
        "reason": s.get("reason"), "stop_detail": s.get("stop_detail"), "report": args.report,
    }, default=str))  # fmt: skip


def _fresh_peak() -> None:
    """Give the C heap's free memory back and restart the peak from the resident size now."""
    gc.collect()
    try:
        ctypes.CDLL(None).malloc_trim(0)
        Path("/proc/self/clear_refs").write_text("5")
    except (AttributeError, OSError):
        pass  # not glibc or not Linux: the peak keeps the warm-up's


if __name__ == "__main__":
    main()
