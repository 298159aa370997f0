"""The navigation's cost per step once nothing is left to explore (issue 52): one exploration
kept going after its frontiers ran out, in the checkout given. Prints one JSON line.

    .venv/bin/python benchmarks/bench_after_explored.py --tree . [--world office_a]
        [--slam rbpf|odometry|oracle] [--seed 1] [--time-limit 950]
    OTHER/.venv/bin/python THIS/benchmarks/bench_after_explored.py --tree OTHER ...

The stop rules that end a finished run (no_frontier after explore.no_frontier_time, stuck
after stuck_timeout, map_unchanged every snapshot_period) are pushed past the time limit, so
the robot stands with no frontier to go to until then, as a run whose frontiers are all out
of reach does for up to stuck_timeout. Per 0.1 s step: the navigation stack's CPU time
(`ExplorationResult.nav_cpu_s`, this thread) and the whole step's wall time (everything the
loop does, the wall clock: read it under the load it was taken at) in the steps whose status
is "no_frontier" and in the others. `oracle`: the odometry SLAM fed the true pose (a perfect
map). Uses only what benchmarks/explore_digest.py uses (load_world, Simulator, make_slam,
explore), so one driver times both trees.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def _tree_api(tree: Path):
    """The functions this benchmark calls, from `tree`'s own code (either layout)."""
    sys.path.insert(0, str(tree))
    from worker.explore.loop import ExploreParams, explore
    from worker.sim.simulator import SimParams, Simulator

    try:  # the tree's own layout: after issue 53, make_slam and grouped explore parameters
        from worker.explore.flat_params import explore_params
        from worker.slam.registry import make_slam
    except ImportError:
        from worker.slam.base import make_slam

        explore_params = ExploreParams
    from worker.slam.params import SlamParams
    from worker.world.loader import load_world

    return explore, explore_params, make_slam, load_world, SimParams, Simulator, SlamParams


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, required=True, help="the checkout whose code runs")
    ap.add_argument("--world", default="office_a", help="a Bormann world's name")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=950.0, help="[s] simulated")
    args = ap.parse_args()
    tree = args.tree.resolve()
    explore, explore_params, make_slam, load_world, SimParams, Simulator, SlamParams = _tree_api(
        tree
    )
    world = load_world(tree / "worlds" / "bormann" / f"{args.world}.yaml")
    rng = np.random.default_rng(args.seed)
    sim_params = SimParams()
    sim = Simulator(world, sim_params, rng)
    oracle = args.slam == "oracle"
    slam = make_slam("odometry" if oracle else args.slam, sim_params.laser, SlamParams(), rng)
    never = 10.0 * args.time_limit
    params = explore_params(
        time_limit=args.time_limit, progress_period=0.1, no_frontier_time=never,
        stuck_timeout=never, snapshot_period=never,
    )  # fmt: skip
    statuses: list[str] = []
    stamps: list[float] = []  # [s] wall clock at each step's progress call

    def on_progress(p) -> None:
        statuses.append(p.status)
        stamps.append(time.perf_counter())

    wall0 = time.perf_counter()
    ex = explore(world, sim, slam, params, oracle=oracle, on_progress=on_progress)
    wall = time.perf_counter() - wall0
    rest = np.array([s == "no_frontier" for s in statuses], dtype=bool)
    cpu = ex.nav_cpu_s[: len(rest)]
    # each step's whole wall time (simulator, SLAM, navigation, stop rules), from one
    # progress call to the next
    step_wall = np.diff(np.array([wall0, *stamps]))
    first = float(ex.t[np.argmax(rest)]) if rest.any() else None
    ms = {
        "nav_cpu_ms_exploring": float(np.mean(cpu[~rest])) * 1e3,
        "nav_cpu_ms_no_frontier": float(np.mean(cpu[rest])) * 1e3 if rest.any() else None,
        "nav_cpu_ms_no_frontier_max": float(np.max(cpu[rest])) * 1e3 if rest.any() else None,
        "step_wall_ms_exploring": float(np.mean(step_wall[~rest])) * 1e3,
        "step_wall_ms_no_frontier": float(np.mean(step_wall[rest])) * 1e3 if rest.any() else None,
    }
    out = {
        "tree": str(tree), "world": args.world, "slam": args.slam, "reason": ex.reason,
        "goals": len(ex.goals), "first_no_frontier_s": first, "steps_no_frontier": int(rest.sum()),
        **{k: None if v is None else round(v, 3) for k, v in ms.items()},
        "nav_cpu_s_total": round(float(np.sum(ex.nav_cpu_s)), 2), "wall_s": round(wall, 1),
        "sim_s": round(float(ex.t[-1]), 1),
    }  # fmt: skip
    print(json.dumps(out))


if __name__ == "__main__":
    main()
