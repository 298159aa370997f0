"""How often the safety controller's rules stop the robot for nothing, and miss what is there.

Runs explorations with a noisy laser and, at every moment the safety controller is asked to
judge a forward command, scores each rule below on the noisy scan the robot got against the
noise-free scan of the same instant (`Simulator.scan_noise_free`): an obstacle is really in
the way when the noise-free scan has a hit within `safety_distance` of the footprint's front
in the band it sweeps. For each rule it prints how many of those moments it would stop at,
how many of these stops were false alarms, and how many real obstacles it would let pass
(also those within 0.1 m). The explorations drive with the defaults' rule; every rule is
scored on the same moments.

With --drive-noise-free the robot drives on a noise-free laser (where the safety controller
meets real obstacles: a thin leg the costmaps missed) and every moment is scored on --draws
noisy scans made from its noise-free one (Gaussian range noise of --noise, seeded): how
many real obstacles each rule would miss on a noisy laser.

    .venv/bin/python benchmarks/bench_safety.py [--worlds office_d_furnitures,Freiburg79_scan]
        [--seeds 1-3] [--noise 0.1] [--slam oracle|rbpf] [--time-limit 900] [--params FILE]
        [--drive-noise-free [--draws 20]]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.explore.flat_params import explore_params  # noqa: E402
from worker.explore.loop import Exploration, ExploreParams  # noqa: E402
from worker.explore.safety import front_clearance, median_ranges  # noqa: E402
from worker.param_io import load_params_file  # noqa: E402
from worker.sim.params import SimParams  # noqa: E402
from worker.sim.simulator import Simulator, add_range_noise  # noqa: E402
from worker.slam.params import SlamParams  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402
from worker.world.loader import load_world  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_explore import world_path  # noqa: E402

# (name, median beams, slack in units of the laser's noise sigma, min points)
RULES = (
    ("raw", 1, 0.0, 1),
    ("median 3", 3, 0.0, 1),
    ("median 3, slack 1 sigma", 3, 1.0, 1),
    ("median 3, slack 2 sigma", 3, 2.0, 1),
    ("median 3, min points 4", 3, 0.0, 4),
    ("raw, min points 4", 1, 0.0, 4),
    ("median 3, slack 1 sigma, min 2", 3, 1.0, 2),
)


class _Moments:
    """The safety controller's decisions, recorded: the noisy and the noise-free scan of
    every moment it judged a forward command."""

    def __init__(self, sim: Simulator):
        self.sim = sim
        self.noisy: list[np.ndarray] = []
        self.true: list[np.ndarray] = []

    def wrap(self, safety) -> None:
        check = safety.check

        def recorded(t, ranges_m, v_cmd):
            if v_cmd > 0.0 and not safety.active(t):
                self.noisy.append(np.array(ranges_m, dtype=float))
                self.true.append(self.sim.scan_noise_free())
            return check(t, ranges_m, v_cmd)

        safety.check = recorded


def _fires(ranges, angles, range_max, p: ExploreParams, sigma, median, k, n) -> bool:
    half, lateral = p.costmap.footprint_half_m, p.costmap.footprint_padding
    d, _ = front_clearance(median_ranges(ranges, median), angles, range_max, half, lateral,
                           k * sigma, n)  # fmt: skip
    return d < p.safety.safety_distance


def run(name: str, seed: int, args) -> tuple[_Moments, object, ExploreParams]:
    world = load_world(world_path(name))
    rng = np.random.default_rng(seed)
    sim_params = SimParams(laser_noise_sigma=0.0 if args.drive_noise_free else args.noise)
    sim = Simulator(world, sim_params, rng)
    oracle = args.slam == "oracle"
    slam = make_slam("odometry" if oracle else args.slam, sim_params.laser, SlamParams(), rng)
    extra = load_params_file(args.params).get("explore", {}) if args.params else {}
    params = explore_params(time_limit=args.time_limit, **extra)
    loop = Exploration(world, sim, slam, params, oracle, None)
    moments = _Moments(sim)
    moments.wrap(loop.nav.safety)
    stop = None
    while stop is None:
        stop = loop.step()
    return moments, loop.result(stop), params


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", default="office_d_furnitures,Freiburg79_scan")
    ap.add_argument("--seeds", default="1-3", help="A-B or A")
    ap.add_argument("--noise", type=float, default=0.1, help="laser range noise sigma [m]")
    ap.add_argument("--slam", default="oracle", help="oracle, rbpf, ...")
    ap.add_argument("--time-limit", type=float, default=900.0)
    ap.add_argument("--params", help="a run parameter file (its `explore` keys are used)")
    ap.add_argument(
        "--drive-noise-free",
        action="store_true",
        help="drive on a noise-free laser, score on noisy scans made from it",
    )
    ap.add_argument("--draws", type=int, default=20, help="noisy scans per moment")
    args = ap.parse_args()
    if args.noise <= 0.0:
        print(
            "bench_safety: --noise must be > 0 (a noise-free laser's rules agree)", file=sys.stderr
        )
        raise SystemExit(2)
    a, _, b = args.seeds.partition("-")
    try:
        args.seed_range = range(int(a), int(b or a) + 1)
    except ValueError:
        print(f"bench_safety: --seeds must be A or A-B, not {args.seeds!r}", file=sys.stderr)
        raise SystemExit(2) from None
    return args


def _judge(moments: _Moments, p: ExploreParams, seed: int, args, tally, counts) -> None:
    """Each rule's verdict on each moment of a run (its scans, or noisy draws of its true
    ones), added to `tally` (per rule: stops, false stops, missed obstacles, missed within
    0.1 m) and `counts` (moments, with an obstacle really in the way, within 0.1 m)."""
    laser = SimParams().laser
    angles = laser.angles
    draw_rng = np.random.default_rng([seed, 7])
    c = p.costmap
    for noisy, true in zip(moments.noisy, moments.true, strict=True):
        d_true, _ = front_clearance(
            true, angles, laser.range_max, c.footprint_half_m, c.footprint_padding
        )
        real = d_true < p.safety.safety_distance
        close = d_true < 0.1
        scans = [noisy]
        if args.drive_noise_free:  # the laser read it noise-free: noisy versions
            scans = [
                add_range_noise(true, args.noise, laser.range_max, draw_rng)
                for _ in range(args.draws)
            ]
        for scan in scans:
            counts += (1, real, close)
            for rule, median, k, n in RULES:
                fired = _fires(scan, angles, laser.range_max, p, args.noise, median, k, n)
                tally[rule] += (fired, fired and not real, real and not fired,
                                close and not fired)  # fmt: skip


def main() -> None:
    args = _args()
    # per rule: stops, false stops, missed obstacles, missed within 0.1 m
    tally = {r[0]: np.zeros(4, dtype=int) for r in RULES}
    counts = np.zeros(3, dtype=int)  # moments, with an obstacle in the way, within 0.1 m
    print(f"{time.strftime('%H:%M UTC', time.gmtime())}, load {os.getloadavg()[0]:.1f}; "
          f"noise {args.noise} m, {args.slam}")  # fmt: skip
    for name in args.worlds.split(","):
        for seed in args.seed_range:
            moments, result, p = run(name, seed, args)
            print(f"{name} seed {seed}: {result.outcome} ({result.reason}) at "
                  f"{result.t[-1]:.0f} s, coverage {result.coverage:.3f}, "
                  f"{len(moments.noisy)} moments, "
                  f"{result.safety_triggers} safety stops")  # fmt: skip
            _judge(moments, p, seed, args, tally, counts)
    n_moments, n_real, n_close = (int(v) for v in counts)
    print(f"\n{n_moments} moments judged, {n_real} with an obstacle really in the way "
          f"({n_close} within 0.1 m)\n")  # fmt: skip
    print("| rule | stops | false stops | missed obstacles | missed within 0.1 m |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for rule, *_ in RULES:
        s, f, m, c = tally[rule]
        print(f"| {rule} | {s} | {f} | {m} of {n_real} | {c} of {n_close} |")


if __name__ == "__main__":
    main()
