"""Does the map score tell the truth? Runs spanning good to bad maps, and Spearman's rho between
their relation errors and their map-versus-floorplan scores (issue 17 section 4).

    .venv/bin/python benchmarks/bench_validity.py [--out out/validity] [--time-limit 90]
        [--seeds 1 2] [--worlds worlds/bormann/office_a.yaml worlds/bormann/lab_ipa.yaml]
        [--noises 0 0.1 0.3] [--limit N] [--report-only] [--plot docs/validity.png]
        [--walls density|ridge|front|occupied] [--trajectory final|online]

Every run (rbpf with 40, 10, 3 and 1 particles and the odometry baseline; laser noise 0, 0.1
and 0.3 m; each world and seed) is written to OUT/<key>.json as soon as it ends, and a run
already there is not run again: stop it any time and start it again to resume. The runs are
ordered seed first, so any prefix spans the algorithms, noises and worlds. The odometry error
is 5x Stage's default (E = 0.05, 0.05, 0.10) so that dead reckoning and starved filters make
bad maps within a short time limit. B relations: at least 500 a run (issue 17 section 2).
Each run's final map is kept beside it (OUT/<key>.npz: the hit ratios and end-point counts,
the grid's geometry and the first estimated and true poses), and the report scores the stored
maps again with the map score of the current code (`--walls` picks the wall extraction), so a
change to the score needs no new runs; a run without its map is run again (a summary alone
cannot be scored again).

Each run's relations are scored twice: on the online estimate (each step's pose as the SLAM
gave it then, the one the robot drove on and summary.json scores) and on the SLAM's final
trajectory (rbpf: the best particle's path at the end, GMapping's trajectory tree; the
odometry baseline keeps none, its online estimate is its final one), kept in the run's JSON as
`final_relations` (a run without them is run again). The final map is drawn along the final
trajectory, so that is the trajectory whose error the map score should track;
`--trajectory final` (the default) takes it for the plot, the medians and the rule of thumb,
and the Spearman table has both (`Bfinal`, `SMfinal`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
WORLDS = ("worlds/bormann/office_a.yaml", "worlds/bormann/lab_ipa.yaml")
SLAMS = (("rbpf", 40), ("rbpf", 10), ("rbpf", 3), ("rbpf", 1), ("odometry", 1))
NOISES = (0.0, 0.1, 0.3)  # [m]
ODOM_ERROR = (0.05, 0.05, 0.10)  # [-] Stage E, 5x the default
from validity_report import (  # noqa: E402  (benchmarks/, the script's own folder)
    ERRORS,
    ERRORS_FINAL,
    FINAL_KINDS,
    SCORES,
    report,
    scatter,
)


@dataclass(frozen=True)
class Spec:
    """One run of the benchmark."""

    world: str  # path relative to the repository
    algorithm: str
    particles: int
    noise: float  # [m] laser range noise sigma
    seed: int

    @property
    def key(self) -> str:
        slam = f"rbpf{self.particles}" if self.algorithm == "rbpf" else self.algorithm
        return f"{Path(self.world).stem}-{slam}-n{self.noise:g}-s{self.seed}"

    @property
    def slam(self) -> str:
        return f"rbpf-{self.particles}" if self.algorithm == "rbpf" else self.algorithm


def specs(worlds: list[str], seeds: list[int], noises: tuple[float, ...] = NOISES) -> list[Spec]:
    """All runs, seed first (a prefix spans everything else)."""
    return [
        Spec(w, alg, n, noise, seed)
        for seed in seeds
        for noise in noises
        for w in worlds
        for alg, n in SLAMS
    ]


def run_params(spec: Spec, time_limit: float) -> dict[str, Any]:
    return {
        "algorithm": spec.algorithm,
        "sim": {"laser_noise_sigma": spec.noise, "odom_error": list(ODOM_ERROR)},
        "slam": {"particles": spec.particles},
        "explore": {"time_limit": time_limit},
        "eval": {"b": {"min_relations": 500}},
    }


def run_all(todo: list[Spec], out: Path, time_limit: float) -> None:
    """Run what OUT does not hold yet, one at a time, writing each as it ends."""
    from worker.pipeline import run_one
    from worker.run_params import RunParams
    from worker.world.loader import load_world

    worlds: dict[str, Any] = {}
    for i, spec in enumerate(todo):
        path = out / f"{spec.key}.json"
        if (
            path.exists()
            and path.with_suffix(".npz").exists()
            and "final_relations" in json.loads(path.read_text())
        ):
            continue
        world = worlds.setdefault(spec.world, load_world(ROOT / spec.world))
        t0 = time.perf_counter()
        rec: dict[str, Any] = {"key": spec.key, "world": world.name, "slam": spec.slam,
                               "noise": spec.noise, "seed": spec.seed}  # fmt: skip
        try:
            r = run_one(world, RunParams.from_json(run_params(spec, time_limit)), spec.seed)
            rec["summary"] = r.summary.to_dict()
            rec["final_relations"] = final_errors(r)
            save_map(path.with_suffix(".npz"), r.exploration)
        except Exception as exc:  # a run that raises is recorded, the rest go on
            rec["error"] = f"{type(exc).__name__}: {exc}"
        rec["wall_s"] = time.perf_counter() - t0
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(rec) + "\n")
        tmp.replace(path)
        utc = time.strftime("%H:%M:%S", time.gmtime())
        print(f"[{utc} UTC] {i + 1}/{len(todo)} {spec.key}: {rec['wall_s']:.0f} s", flush=True)


def final_errors(r: Any) -> dict[str, dict[str, float]] | None:
    """Mean errors of the run's final trajectory on the run's own B and SM relations ({kind:
    {"translation": m, "rotation": rad}}), None where the SLAM keeps no final trajectory."""
    from worker.evaluate.metric import evaluate_relations
    from worker.evaluate.trajectory import Trajectory

    ex = r.exploration
    if ex.pose_final is None:
        return None
    final = Trajectory(ex.t, ex.pose_final)
    out = {}
    for kind in FINAL_KINDS:
        if kind not in r.relations:
            continue
        s = evaluate_relations(r.relations[kind], final, r.params.eval.max_gap).summary()
        if s["translation"]["n"]:
            out[kind] = {axis: s[axis]["mean"] for axis in ("translation", "rotation")}
    return out


def save_map(path: Path, ex: Any) -> None:
    """The final map and the poses its score starts from, so that it can be scored again."""
    if len(ex.pose_gt) == 0:
        return
    g = ex.final_map
    tmp = path.with_suffix(".tmp.npz")
    hits = {} if g.hits is None else {"hits": g.hits}
    np.savez_compressed(tmp, prob=g.prob, resolution=g.resolution, origin=g.origin,
                        occ_thresh=g.occ_thresh, pose_est0=ex.pose_est[0],
                        pose_gt0=ex.pose_gt[0], **hits)  # fmt: skip
    tmp.replace(path)


def rescore(npz: Path, world_path: Path, p: Any, cache: dict[str, Any]) -> dict[str, Any]:
    """The map score of a stored map, computed again (as worker.pipeline scores a run)."""
    from worker.evaluate.coverage import reachable_free
    from worker.evaluate.map_score import score_map, start_alignment
    from worker.explore.params import ExploreParams
    from worker.slam.grid import OccupancyGrid
    from worker.world.loader import load_world

    d = np.load(npz)
    world = cache.get(str(world_path)) or cache.setdefault(str(world_path), load_world(world_path))
    g0 = d["pose_gt0"]
    start = (int(math.floor((g0[0] - world.origin[0]) / world.resolution)),
             int(math.floor((g0[1] - world.origin[1]) / world.resolution)))  # fmt: skip
    key = f"reach {world_path} {start}"
    if key not in cache:
        cache[key] = reachable_free(world.occ, world.resolution, start,
                                    ExploreParams().costmap.footprint_half_m)  # fmt: skip
    hits = d["hits"] if "hits" in d.files else None  # maps stored before the counts: none
    grid = OccupancyGrid(
        d["prob"], float(d["resolution"]), d["origin"], float(d["occ_thresh"]), hits
    )
    T0 = start_alignment(d["pose_est0"], g0)
    return score_map(world.occ, world.resolution, world.origin, cache[key], grid, T0, p).summary()


def load(out: Path, p: Any = None, world_paths: tuple[str, ...] = WORLDS) -> list[dict[str, Any]]:
    """The finished runs in OUT that have a B error and a map score; a run whose map is
    stored (OUT/<key>.npz) is scored again with `p` (MapScoreParams), the others keep the
    score their summary holds."""
    rows: list[dict[str, Any]] = []
    cache: dict[str, Any] = {}
    worlds = {Path(w).stem: ROOT / w for w in world_paths}
    for path in sorted(out.glob("*.json")):
        rec = json.loads(path.read_text())
        s = rec.get("summary")
        if not s or not s.get("map_score") or "B" not in s["relations"]:
            continue
        npz = path.with_suffix(".npz")
        if p is not None and npz.exists() and rec["world"] in worlds:
            pr = p.for_laser_noise(rec["noise"])  # as the run's own score was made
            s["map_score"] = rescore(npz, worlds[rec["world"]], pr, cache)
        row = {k: rec[k] for k in ("key", "world", "slam", "noise", "seed")}
        row["outcome"] = s["outcome"]
        for kind, axis in ERRORS:
            rel = s["relations"].get(kind)
            row[f"{kind}_{axis}"] = rel[axis]["mean"] if rel else None
        # "final_relations" absent: a run made before they were kept (its final trajectory is
        # unknown); None: the SLAM keeps no final trajectory, its online estimate is its final
        fin = rec.get("final_relations", {})
        for kind, axis in ERRORS_FINAL:
            base = kind.removesuffix("final")
            if fin is None:
                row[f"{kind}_{axis}"] = row[f"{base}_{axis}"]
            else:
                row[f"{kind}_{axis}"] = fin.get(base, {}).get(axis)
        row.update({k: s["map_score"][k] for k in SCORES})
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="out/validity", help="one JSON per run (resumable)")
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS))
    ap.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--noises", nargs="+", type=float, default=list(NOISES), help="[m]")
    ap.add_argument("--time-limit", type=float, default=90.0, help="[s] simulated")
    ap.add_argument("--limit", type=int, default=None, help="run only the first N runs")
    ap.add_argument("--report-only", action="store_true", help="no new runs")
    ap.add_argument("--walls", default="density",
                    choices=("density", "ridge", "front", "occupied"),
                    help="the map's walls, when stored maps are scored again")  # fmt: skip
    ap.add_argument("--plot", default=None, help="scatter plot PNG (default OUT/validity.png)")
    ap.add_argument(
        "--trajectory",
        default="final",
        choices=("final", "online"),
        help="whose B error the plot, the medians and the rule of thumb take: the final "
        "trajectory (the final map's own) or the online estimate",
    )
    args = ap.parse_args()
    if args.time_limit <= 0 or (args.limit is not None and args.limit < 1):
        print("bench_validity: --time-limit and --limit must be positive", file=sys.stderr)
        sys.exit(2)
    if any(n < 0 for n in args.noises):
        print("bench_validity: --noises must be >= 0", file=sys.stderr)
        sys.exit(2)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    todo = specs(args.worlds, args.seeds, tuple(args.noises))[: args.limit]
    if not args.report_only:
        run_all(todo, out, args.time_limit)
    from worker.evaluate.map_score import MapScoreParams

    p = MapScoreParams(walls=args.walls)
    rows = load(out, p, tuple(args.worlds))
    b = "Bfinal" if args.trajectory == "final" else "B"
    print(report(rows, p.tolerance, b))
    if rows:
        plot = Path(args.plot) if args.plot else out / "validity.png"
        scatter(rows, plot, b)
        print(f"scatter plot: {plot}")


if __name__ == "__main__":
    main()
