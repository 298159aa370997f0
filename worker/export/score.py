"""Score an external estimate on a run's own relations and write its report: `score_estimate`.

The relations are read from the run's report folder (relations_B.txt, _A, _SM), never drawn
again: B's count depends on the estimate it was drawn for, so re-drawing would give the two
algorithms different relations. The estimate's report goes to `<run>/estimates/<name>/`:
summary.json, T.errors / R.errors and errors.png (on B), trajectories.png, est.tum, est.log.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from worker.errors import InputError
from worker.evaluate.ate import absolute_trajectory_error
from worker.evaluate.metric import RelationErrors, evaluate_relations
from worker.evaluate.textio import write_text
from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import (
    read_relations,
    read_trajectory,
    write_carmen,
    write_errors,
    write_tum,
)
from worker.export.checks import CheckParams, check_estimate
from worker.report.summary import RunSummary

ESTIMATES_DIR = "estimates"
KINDS = ("B", "A", "SM")
# the files of a run's report folder scoring reads (fetched alone from object storage)
RUN_PARTS = ("summary.json", "gt.tum", *(f"relations_{k}.txt" for k in KINDS), "map.yaml",
             "map.pgm")  # fmt: skip
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,39}$")


@dataclass(frozen=True, eq=False)
class EstimateScore:
    """An estimate scored on a run: its relation errors per kind, ATE, and summary.json."""

    name: str
    errors: dict[str, RelationErrors]
    summary: dict[str, Any]
    folder: Path


def check_name(name: str) -> str:
    """The name of an estimate: 1-40 letters, digits, `_ . -`, not starting with a sign."""
    if not NAME_RE.match(name):
        raise InputError(
            f"estimate name {name!r}: 1-40 letters, digits, '_', '.', '-' (first a letter or digit)"
        )
    return name


def _run_parts(run_dir: Path) -> tuple[RunSummary, Trajectory, dict[str, Any]]:
    """(summary, ground truth, relations by kind) of a run's report folder."""
    if not (run_dir / "summary.json").is_file():
        raise InputError("not a run's report folder (no summary.json)", path=run_dir)
    try:
        summary = RunSummary.load(json.loads((run_dir / "summary.json").read_text()))
    except ValueError as exc:
        raise InputError(
            f"summary.json cannot be read ({exc.__class__.__name__})", path=run_dir
        ) from None
    if summary is None:
        raise InputError("summary.json is empty", path=run_dir)
    gt = read_trajectory(run_dir / "gt.tum", "tum")
    relations = {k: read_relations(run_dir / f"relations_{k}.txt") for k in KINDS
                 if (run_dir / f"relations_{k}.txt").is_file()}  # fmt: skip
    if "B" not in relations:
        raise InputError("the run has no relations_B.txt to score on", path=run_dir)
    return summary, gt, relations


def score_estimate(run_dir: str | Path, est: Trajectory, name: str, source: str,
                   max_gap: float | None = None, checks: CheckParams | None = None,
                   out_dir: str | Path | None = None) -> EstimateScore:  # fmt: skip
    """Check `est` against the run's ground truth, score it on the run's B, A and SM relations
    (max_gap [s]: the run's own unless given), and write its report folder (default
    `<run_dir>/estimates/<name>`)."""
    run_dir = Path(run_dir)
    check_name(name)
    summary, gt, relations = _run_parts(run_dir)
    check_estimate(est, gt, checks or CheckParams(), name)
    gap = float(summary.params.get("eval", {}).get("max_gap", 0.1)) if max_gap is None else max_gap
    errors = {k: evaluate_relations(rel, est, gap) for k, rel in relations.items()}
    if errors["B"].translation.shape[0] and not errors["B"].evaluated.any():
        raise InputError(
            f"{name}: no B relation could be evaluated: its poses are more than {gap} s "
            "apart (--max-gap)"
        )
    ate = absolute_trajectory_error(gt, est, gap) if len(gt) > 1 else None
    doc = {
        "name": name,
        "source": source,
        "run": {"world": summary.world, "seed": summary.seed, "algorithm": summary.algorithm},
        "relations": {k: e.summary() for k, e in errors.items()},
        "ate": None if ate is None else ate.summary(),
        "n_poses": len(est),
        "t_start": float(est.t[0]),
        "t_end": float(est.t[-1]),
        "max_gap": gap,
    }
    folder = Path(out_dir) if out_dir is not None else run_dir / ESTIMATES_DIR / name
    _write_folder(folder, doc, errors["B"], est, gt, run_dir)
    return EstimateScore(name, errors, doc, folder)


def _write_folder(folder: Path, doc: dict, b: RelationErrors, est: Trajectory, gt: Trajectory,
                  run_dir: Path) -> None:  # fmt: skip
    from worker.report.plots import errors_png, trajectories_png

    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"cannot create directory: {exc.strerror}", path=folder) from None
    write_text(folder / "summary.json", json.dumps(doc, indent=2) + "\n")
    ok = b.evaluated
    write_errors(folder / "T.errors", b.t1[ok], b.t2[ok], b.translation[ok])
    write_errors(folder / "R.errors", b.t1[ok], b.t2[ok], b.rotation[ok])
    errors_png(folder / "errors.png", b.t2[ok], b.translation[ok], b.rotation[ok],
               title=f"B-relation errors of {doc['name']} along the run")  # fmt: skip
    write_tum(folder / "est.tum", est)
    write_carmen(folder / "est.log", est)
    occ, res, origin = _background(run_dir)
    run = doc["run"]
    title = f"{run['world']}, seed {run['seed']}: {doc['name']} (estimate) against the ground truth"
    inside = (est.t >= gt.t[0]) & (est.t <= gt.t[-1])
    trajectories_png(
        folder / "trajectories.png", occ, res, origin, gt.poses, est.poses[inside], title
    )


def _background(run_dir: Path) -> tuple[np.ndarray, float, tuple[float, float]]:
    """The run's final map (occupied cells, bottom row first) to draw the paths on."""
    from PIL import Image

    from worker.world.refs import read_map_yaml

    try:
        meta = read_map_yaml(run_dir / "map.yaml")
        grey = np.asarray(Image.open(run_dir / str(meta["image"])).convert("L"))
        origin = meta.get("origin", [0.0, 0.0, 0.0])
        return (
            np.flipud(grey < 100),
            float(meta["resolution"]),
            (float(origin[0]), float(origin[1])),
        )
    except (OSError, KeyError, ValueError, InputError):
        return np.zeros((10, 10), dtype=bool), 1.0, (0.0, 0.0)
