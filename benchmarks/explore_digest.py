"""Fingerprints of closed-loop explorations: proof that a refactor of worker/explore kept them.

Runs a few explorations (Bormann worlds, oracle and rbpf SLAM, fixed seeds, time limits) and
hashes everything deterministic they produce: timestamps, ground-truth and estimated poses,
the navigation status of every control period, the goals and how they ended, the counters,
the outcome and the final map. Save the digests before a change, compare after it:

    .venv/bin/python benchmarks/explore_digest.py --save /tmp/before.json
    .venv/bin/python benchmarks/explore_digest.py --compare /tmp/before.json

Wall and CPU times are left out (they differ from run to run); all else must match bit for bit.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import sys
from collections import Counter
from pathlib import Path

import numpy as np

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.explore.flat_params import explore_params  # noqa: E402
from worker.explore.loop import ExploreProgress, explore  # noqa: E402
from worker.sim.simulator import SimParams, Simulator  # noqa: E402
from worker.slam.params import SlamParams  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402
from worker.world.loader import load_world  # noqa: E402

# (world, slam, seed, time limit [s], other ExploreParams, flat keys as the digests saved
# before the groups name them): furniture worlds exercise the
# safety controller, a plain one goes to the end of its exploration; impatient settings give
# goals up (back-outs, blacklists, their retry), a room behind a slit makes planning fail
RUNS = (
    ("lab_ipa_furnitures", "oracle", 1, 600.0, {}),
    ("office_b_furnitures", "rbpf", 2, 300.0, {}),
    ("Freiburg52_scan", "oracle", 1, 1800.0, {}),
    ("test:dead_end", "oracle", 3, 600.0, {}),
    ("test:dead_end", "rbpf", 4, 300.0, {}),
    ("test:unreachable", "oracle", 3, 900.0, {}),
    (
        "office_b_furnitures",
        "oracle",
        5,
        300.0,
        {"progress_timeout": 6.0, "controller_patience": 3.0},
    ),
)


def _world(name: str):
    """A bundled Bormann world, or `test:dead_end` (the exploration tests' dead-end corridor)."""
    if name == "test:dead_end":
        from tests.worker.explore.test_loop import _dead_end_world

        return _dead_end_world()
    if name == "test:unreachable":  # as test_unreachable_regions_do_not_keep_the_robot_busy
        from tests.worker.explore.test_loop import _box, _cells
        from worker.world.world import World

        occ = _box(5.0, 9.0)
        occ[:, _cells(5.0) : _cells(5.1)] = True
        occ[_cells(2.4) : _cells(2.65), _cells(5.0) : _cells(5.1)] = False  # the slit
        occ[_cells(3.5) : _cells(3.6), _cells(5.1) :] = True  # the closed cell's floor
        return World.from_array(occ, 0.05, start_pose=(1.5, 1.5, 0.0), name="unreachable")
    return load_world(ROOT / "worlds" / "bormann" / f"{name}.yaml")


def digest(name: str, slam_name: str, seed: int, time_limit: float, other: dict) -> dict:
    """One exploration's deterministic output, hashed, with a few readable counters."""
    world = _world(name)
    rng = np.random.default_rng(seed)
    sim_params = SimParams()
    sim = Simulator(world, sim_params, rng)
    oracle = slam_name == "oracle"
    slam = make_slam("odometry" if oracle else slam_name, sim_params.laser, SlamParams(), rng)
    steps: list[tuple] = []

    def on_progress(pr: ExploreProgress) -> None:
        goal = None if pr.goal_xy is None else pr.goal_xy.tobytes()
        plan = None if pr.plan is None else np.asarray(pr.plan).tobytes()
        steps.append((pr.t, str(pr.status), pr.goals_reached, pr.coverage, goal, plan))

    # progress every control period: the status of each step goes into the digest
    params = explore_params(time_limit=time_limit, progress_period=0.1, **other)
    r = explore(world, sim, slam, params, oracle=oracle, on_progress=on_progress)
    h = hashlib.sha256()
    for a in (r.t, r.pose_gt, r.pose_est, r.T_world_map, r.final_map.prob):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr(steps).encode())
    h.update(repr([dataclasses.astuple(g) for g in r.goals]).encode())
    # the outcome and the reason as plain strings: an enum member and its value digest alike
    reason = None if r.reason is None else str(r.reason)
    tail = (str(r.outcome), reason, r.stop_detail, r.path_length_m, r.coverage, r.collision)
    counts = (r.goals_reached, r.goals_failed, r.safety_triggers, r.recoveries)
    h.update(repr((tail, counts)).encode())
    statuses = Counter(s[1] for s in steps)
    return {
        "run": _key((name, slam_name, seed, time_limit, other)),
        "sha256": h.hexdigest(),
        "reason": r.reason,
        "t_end": float(r.t[-1]),
        "goals": len(r.goals),
        "goal_status": dict(Counter(g.status for g in r.goals)),
        "recoveries": r.recoveries,
        "safety": r.safety_triggers,
        "statuses": dict(statuses),
    }


def _key(run: tuple) -> str:
    name, slam_name, seed, time_limit, other = run
    extra = "".join(f"/{k}={v:g}" for k, v in other.items())
    return f"{name}/{slam_name}/seed{seed}/{time_limit:g}s{extra}"


def _matches(run: tuple, patterns: str) -> bool:
    return any(pat in _key(run) for pat in patterns.split(","))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", default="", help="write the digests to this JSON file")
    ap.add_argument("--compare", default="", help="compare with digests saved earlier")
    ap.add_argument("--only", default="", help="run only the runs whose key holds one of these")
    ap.add_argument("--skip", default="", help="skip the runs whose key holds one of these")
    args = ap.parse_args()
    runs = [r for r in RUNS if not args.only or _matches(r, args.only)]
    runs = [r for r in runs if not args.skip or not _matches(r, args.skip)]
    out = []
    for run in runs:
        d = digest(*run)
        out.append(d)
        print(json.dumps(d), flush=True)
    if args.save:
        Path(args.save).write_text(json.dumps(out, indent=1) + "\n")
    if args.compare:
        before = {d["run"]: d for d in json.loads(Path(args.compare).read_text())}
        bad = [d["run"] for d in out if before.get(d["run"], {}).get("sha256") != d["sha256"]]
        print("DIFFERENT: " + ", ".join(bad) if bad else f"all {len(out)} identical")
        sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
