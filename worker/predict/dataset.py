"""The training set of the map-quality predictor: batch tables (runs.csv) joined with the
features of each run's world, one row per (world, SLAM algorithm)."""

from __future__ import annotations

import csv
import math
from collections import defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.errors import InputError
from worker.world.features import WorldFeatures, numeric_names

FURNITURE_SUFFIXES = ("_furnitures", "_furniture")


def building_of(world: str) -> str:
    """The building a world belongs to: its name without a furniture suffix (a building and
    its furnished variant are one group in cross-validation)."""
    for suffix in FURNITURE_SUFFIXES:
        if world.endswith(suffix):
            return world[: -len(suffix)]
    return world


@dataclass(frozen=True)
class WorldRuns:
    """The runs of one world with one SLAM algorithm."""

    world: str
    slam: str
    runs: int  # runs in the tables
    evaluated: int  # runs with a B evaluation
    completed: int  # runs whose exploration completed
    b_mean_t: float  # [m] mean over the evaluated runs of their mean B translational error
    b_mean_r: float  # [rad] the same, rotational


def read_runs(paths: Sequence[Path]) -> list[dict[str, str]]:
    """The rows of the runs.csv of each batch folder (or runs.csv file) in `paths`."""
    rows: list[dict[str, str]] = []
    for p in paths:
        path = p / "runs.csv" if p.is_dir() else p
        if not path.is_file():
            raise InputError("no runs.csv here (give a batch output folder)", path=p)
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            missing = {"world", "slam", "outcome", "b_mean_t", "b_mean_r"} - set(
                reader.fieldnames or ()
            )
            if missing:
                raise InputError(f"runs.csv lacks the columns {sorted(missing)}", path=path)
            rows.extend(reader)
    if not rows:
        raise InputError("the batch tables hold no runs")
    return rows


def _number(text: str | None) -> float:
    try:
        return float(text) if text not in (None, "") else math.nan
    except ValueError:
        return math.nan


def aggregate(rows: Iterable[dict[str, str]]) -> list[WorldRuns]:
    """Per (world, slam): counts and mean B errors (as the thesis's Tables 6.4/6.5, but over
    every evaluated run: short runs stop on the time limit and count as failed)."""
    groups: dict[tuple[str, str], list[dict[str, str]]] = defaultdict(list)
    for r in rows:
        if _number(r.get("noise") or "0") == 0.0:  # the thesis default: no laser noise
            groups[(r["world"], r["slam"])].append(r)
    out = []
    for (world, slam), rs in sorted(groups.items()):
        t = np.array([_number(r["b_mean_t"]) for r in rs])
        rot = np.array([_number(r["b_mean_r"]) for r in rs])
        ok = np.isfinite(t) & np.isfinite(rot)
        out.append(
            WorldRuns(
                world=world,
                slam=slam,
                runs=len(rs),
                evaluated=int(ok.sum()),
                completed=sum(r["outcome"] == "completed" for r in rs),
                b_mean_t=float(t[ok].mean()) if ok.any() else math.nan,
                b_mean_r=float(rot[ok].mean()) if ok.any() else math.nan,
            )
        )
    return out


@dataclass(frozen=True)
class Dataset:
    """One SLAM algorithm's training rows: features X `(N, F)` and targets `(N,)`."""

    slam: str
    names: tuple[str, ...]  # feature names, the columns of X
    worlds: tuple[str, ...]
    buildings: tuple[str, ...]  # the CV groups
    X: np.ndarray  # (N, F)
    b_mean_t: np.ndarray  # (N,) [m]
    b_mean_r: np.ndarray  # (N,) [rad]
    runs: np.ndarray  # (N,) int
    completed: np.ndarray  # (N,) int


def feature_row(features: WorldFeatures, names: Sequence[str]) -> np.ndarray:
    """`(F,)` float64: the named numeric features."""
    d = features.as_dict()
    return np.array([float(d[n]) for n in names])


def build_datasets(
    rows: Iterable[dict[str, str]], features: Callable[[str], WorldFeatures]
) -> dict[str, Dataset]:
    """Per SLAM algorithm, the evaluated worlds joined with `features(world name)`."""
    names = numeric_names()
    per_slam: dict[str, list[WorldRuns]] = defaultdict(list)
    for wr in aggregate(rows):
        if wr.evaluated:
            per_slam[wr.slam].append(wr)
    out = {}
    for slam, wrs in per_slam.items():
        X = np.stack([feature_row(features(w.world), names) for w in wrs])
        out[slam] = Dataset(
            slam=slam,
            names=names,
            worlds=tuple(w.world for w in wrs),
            buildings=tuple(building_of(w.world) for w in wrs),
            X=X,
            b_mean_t=np.array([w.b_mean_t for w in wrs]),
            b_mean_r=np.array([w.b_mean_r for w in wrs]),
            runs=np.array([w.runs for w in wrs]),
            completed=np.array([w.completed for w in wrs]),
        )
    if not out:
        raise InputError("no run in the batch tables has a B evaluation to learn from")
    return out


def world_index(folders: Sequence[Path]) -> dict[str, Path]:
    """World name -> floorplan file, from every map_server YAML / .world under `folders`."""
    from worker.world.catalogue import find_worlds

    index: dict[str, Path] = {}
    for folder in folders:
        for p in find_worlds(folder):
            index.setdefault(p.stem, p)
    return index
