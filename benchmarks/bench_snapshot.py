"""Calibrate the map-snapshot stop rule: when would it fire, and was exploration done then?

Runs whole explorations (the rule's own firing switched off, so each run ends as it would
without it) and keeps the SLAM map, thresholded, every --every simulated seconds. Then, for
each run, it prints where the rule would have fired with snapshots g = --period apart, for
the default measure (the share of the known map that changed class beyond one cell) at each
--thresholds, and for the thesis's pixel MSE at e = 5: the time it fires, the coverage of the
reachable free space then, and the run's final coverage and end. A threshold is right when
it fires after the coverage stopped rising and never before.

    .venv/bin/python benchmarks/bench_snapshot.py office_a lab_intel office_d --seeds 1-2
    .venv/bin/python benchmarks/bench_snapshot.py office_a --seeds 1 --fixture F.npz

--fixture keeps the snapshots at multiples of --period of the first run (the test data of
tests/worker/explore/test_snapshot_calibration.py). World names are looked up under
worlds/bormann and worlds/schools, or given as YAML paths.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

os.environ.setdefault("MAPQUAL_SLAM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.explore.stop_rules import map_image, snapshot_change  # noqa: E402
from worker.pipeline import run_one  # noqa: E402
from worker.run_params import RunParams  # noqa: E402
from worker.world.loader import load_world  # noqa: E402


def _world_path(name: str) -> Path:
    p = Path(name)
    if p.suffix in (".yaml", ".yml"):
        return p
    for folder in ("bormann", "schools"):
        q = ROOT / "worlds" / folder / f"{name}.yaml"
        if q.exists():
            return q
    raise SystemExit(f"bench_snapshot: no world {name!r} under worlds/bormann or worlds/schools")


def _seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def record(world, params: RunParams, seed: int, every: float):
    """One run; its snapshots [(t, image, origin, coverage)] and the run's result."""
    snaps: list[tuple[float, np.ndarray, np.ndarray, float]] = []
    due = [every]

    def progress(r) -> None:
        if r.t >= due[0] - 1e-9:
            due[0] += every
            g = r.occupancy()
            img = map_image(g.prob, g.occ_thresh)
            snaps.append((float(r.t), img, np.asarray(g.origin, float)[:2].copy(), r.coverage))

    return snaps, run_one(world, params, seed, progress)


def first_fire(snaps, resolution: float, period: float, test) -> tuple[float, float] | None:
    """(t, coverage) of the first snapshot at a multiple of `period` that `test(change)` passes
    against the one before it, as the rule takes them."""
    at = [s for s in snaps if abs(s[0] / period - round(s[0] / period)) < 1e-6 and s[0] > 0]
    for a, b in zip(at, at[1:], strict=False):
        c = snapshot_change(a[1], a[2], b[1], b[2], resolution, 1)
        if test(c):
            return b[0], b[3]
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("worlds", nargs="+")
    ap.add_argument("--seeds", default="1", help="e.g. 1-3")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--period", type=float, default=300.0, help="g [s]")
    ap.add_argument("--every", type=float, default=30.0, help="snapshot spacing kept [s]")
    ap.add_argument("--thresholds", default="0.005,0.01,0.02", help="changed shares to test")
    ap.add_argument("--fixture", type=Path, help="keep the first run's snapshots here (.npz)")
    a = ap.parse_args()
    if a.period % a.every > 1e-9:
        raise SystemExit("bench_snapshot: --period must be a multiple of --every")
    thresholds = [float(x) for x in a.thresholds.split(",")]
    base = RunParams(algorithm=a.slam)
    # the rule never fires during the recording: each run ends as it would without it
    stop = replace(base.explore.stop, snapshot_period=1e12)
    params = replace(base, explore=replace(base.explore, stop=stop))
    head = f"{'world':<22} {'seed':>4} {'end':>14} {'t_end':>6} {'cov':>6}"
    head += "".join(f" {'share<' + format(x, 'g'):>17}" for x in thresholds)
    print(head + f" {'thesis MSE<5':>17}")
    fixture_done = False
    for name in a.worlds:
        world = load_world(_world_path(name))
        for seed in _seeds(a.seeds):
            snaps, res = record(world, params, seed, a.every)
            ex = res.exploration
            row = f"{world.name:<22} {seed:>4} {ex.reason:>14} {ex.t[-1]:>6.0f} {ex.coverage:>6.3f}"
            tests = [lambda c, x=x: c.share < x for x in thresholds] + [lambda c: c.mse < 5.0]
            for test in tests:
                hit = first_fire(snaps, ex.final_map.resolution, a.period, test)
                row += f" {'never':>17}" if hit is None else f" {hit[0]:>6.0f} s {hit[1]:>6.3f} "
            print(row, flush=True)
            if a.fixture and not fixture_done:
                _save_fixture(a.fixture, snaps, a.period, ex, world.name, seed, a.slam)
                fixture_done = True
    return 0


def _save_fixture(path: Path, snaps, period: float, ex, world: str, seed: int, slam: str) -> None:
    at = [s for s in snaps if abs(s[0] / period - round(s[0] / period)) < 1e-6]
    out = {f"map{i}": s[1] for i, s in enumerate(at)}
    meta = {
        "world": world, "seed": seed, "slam": slam, "end_t": float(ex.t[-1]),
        "end_reason": ex.reason, "end_coverage": ex.coverage,
    }  # fmt: skip
    np.savez_compressed(
        path, t=np.array([round(s[0]) for s in at], dtype=float),
        coverage=np.array([s[3] for s in at]), origin=np.array([s[2] for s in at]),
        resolution=np.float64(ex.final_map.resolution), meta=json.dumps(meta), **out,
    )  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
