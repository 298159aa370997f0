"""The navigation's cost per step once nothing is left to explore (issue 52): one whole run
kept going after its last goal, in the checkout it is started in. Prints one JSON line.

    .venv/bin/python benchmarks/bench_after_explored.py --tree . [--world W] [--slam rbpf]
        [--seed 1] [--time-limit 700]
    OTHER/.venv/bin/python THIS/benchmarks/bench_after_explored.py --tree OTHER ...

The stop rules that end a finished run (no_frontier after explore.no_frontier_time, stuck
after stuck_timeout, map_unchanged every snapshot_period) are pushed past the time limit, so
the robot stands with no frontier to go to until then, as a run whose frontiers are all out
of reach does for up to stuck_timeout. Per 0.1 s step: the navigation stack's CPU time
(`ExplorationResult.nav_cpu_s`, this thread) while a goal was pursued and after the last goal
ended, and the run's wall time. Uses only load_world, RunParams.from_json and run_one, so one
driver times both trees.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, required=True, help="the checkout whose code runs")
    ap.add_argument("--world", default="worlds/bormann/office_a.yaml", help="under --tree")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=700.0, help="[s] simulated")
    args = ap.parse_args()
    sys.path.insert(0, str(args.tree.resolve()))
    from worker.pipeline import run_one
    from worker.run_params import RunParams
    from worker.world.loader import load_world

    world = load_world(args.tree / args.world)
    run_one(world, RunParams.from_json({"algorithm": args.slam, "explore": {"time_limit": 5.0}}), 1)
    never = 10.0 * args.time_limit
    explore = {
        "time_limit": args.time_limit,
        "no_frontier_time": never,
        "stuck_timeout": never,
        "snapshot_period": never,
    }
    params = RunParams.from_json({"algorithm": args.slam, "explore": explore})
    wall0 = time.perf_counter()
    ex = run_one(world, params, args.seed).exploration
    wall = time.perf_counter() - wall0
    last = max((g.t_end for g in ex.goals), default=0.0)
    after = ex.t > last + 1.0
    cpu = ex.nav_cpu_s
    tail = cpu[after] if after.any() else np.full(1, np.nan)
    print(
        json.dumps(
            {
                "reason": ex.reason,
                "goals": len(ex.goals),
                "last_goal_end_s": round(last, 1),
                "steps_after": int(after.sum()),
                "nav_cpu_ms_before": round(1e3 * float(np.mean(cpu[~after])), 3),
                "nav_cpu_ms_after": round(1e3 * float(np.mean(tail)), 3),
                "nav_cpu_ms_after_max": round(1e3 * float(np.max(tail)), 3),
                "nav_cpu_s_total": round(float(np.sum(cpu)), 2),
                "wall_s": round(wall, 1),
                "sim_s": round(float(ex.t[-1]), 1),
            }
        )
    )


if __name__ == "__main__":
    main()
