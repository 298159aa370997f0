"""Real-time factor of a whole run (simulate, explore with SLAM, evaluate, write the report) on
office_a with the thesis settings, and the share of wall time per stage.

Target (issue 6): >= 20x real time on one core.

    .venv/bin/python benchmarks/bench_run.py [--world worlds/bormann/office_a.yaml]
        [--slam rbpf] [--seed 1] [--time-limit 7200] [--slam-threads 1]

--slam-threads 2 gives the scan matcher both cores (slam.threads; the run is the same bit for
bit): the figure a single run reaches on a 2-core machine, beside the one-core target.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default=str(ROOT / "worlds/bormann/office_a.yaml"))
    ap.add_argument("--slam", default="rbpf", choices=["rbpf", "odometry", "oracle", "graph"])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=None, help="[s] simulated")
    ap.add_argument("--slam-threads", type=int, default=1, help="scan-matching threads")
    args = ap.parse_args()
    if args.slam_threads < 1:
        ap.error("--slam-threads must be >= 1")

    from worker.pipeline import RunParams, run_one
    from worker.report.folder import SIM_LOG, write_report
    from worker.world.loader import load_world

    world = load_world(args.world)
    data = {"algorithm": args.slam, "slam": {"threads": args.slam_threads}}
    if args.time_limit is not None:
        data["explore"] = {"time_limit": args.time_limit}
    params = RunParams.from_json(data)
    # warm the numba caches so that the figures are about running, not compiling
    run_one(world, RunParams.from_json({**data, "explore": {"time_limit": 5.0}}), args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        result = run_one(world, params, args.seed, sim_log=Path(tmp) / SIM_LOG)
        t1 = time.perf_counter()
        write_report(result, tmp)
        t2 = time.perf_counter()
    s = result.summary
    t = s["timings"]
    total = t2 - t0
    nav, slam, sim = t["navigation_wall_s"], t["slam_wall_s"], t["simulation_wall_s"]
    other = t["explore_wall_s"] - nav - slam - sim
    print(
        f"{world.name}, seed {args.seed}, {args.slam}, {args.slam_threads} scan-matching "
        f"thread(s): {s['outcome']}"
        f"{' (' + s['reason'] + ')' if s['reason'] else ''}, coverage {s['coverage']:.1%}, "
        f"{t['sim_time_s']:.0f} s simulated"
    )
    print(f"real-time factor, run_one:            {t['sim_time_s'] / (t1 - t0):7.1f}x")
    target = "  (target >= 20x on one core)" if args.slam_threads == 1 else ""
    print(f"real-time factor, with report files:  {t['sim_time_s'] / total:7.1f}x{target}")
    print("share of wall time per stage:")
    for name, v in (
        ("simulation + CARMEN log", sim),
        ("SLAM", slam),
        ("navigation", nav),
        ("exploration loop, other", other),
        ("evaluation", t["evaluate_wall_s"]),
        ("report files", t2 - t1),
    ):
        print(f"  {name:26s} {v:8.2f} s  {100 * v / total:5.1f} %")


if __name__ == "__main__":
    main()
