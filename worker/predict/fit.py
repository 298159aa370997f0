"""`mapqual predict train`'s core: batch tables + world features -> the model file's data."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from datetime import UTC, datetime
from functools import cache
from pathlib import Path
from typing import Any

from worker.errors import InputError
from worker.predict.crossval import INTERVAL, conformal_margin, cross_validate, cv_summary
from worker.predict.dataset import Dataset, build_datasets, read_runs, world_index
from worker.predict.model import FORMAT, VERSION
from worker.predict.train import TrainParams, fit_slam
from worker.world.features import FeatureParams, WorldFeatures, features_of, numeric_names


def feature_source(world_dirs: Sequence[Path], *, allow_outside: bool = False):
    """A cached `name -> WorldFeatures` over the floorplans under `world_dirs`."""
    from worker.world.loader import load_world

    index = world_index(world_dirs)

    @cache
    def features(name: str) -> WorldFeatures:
        if name not in index:
            where = ", ".join(str(d) for d in world_dirs)
            raise InputError(f"world {name!r} of the batch tables is not under {where} (--worlds)")
        return features_of(load_world(index[name], allow_outside=allow_outside))

    return features


def describe(datasets: dict[str, Dataset], batches: Sequence[Path]) -> dict[str, Any]:
    """The training data's description stored in the model."""
    parts = []
    for slam, ds in sorted(datasets.items()):
        parts.append(
            f"{slam}: {len(ds.worlds)} worlds of {len(set(ds.buildings))} buildings, "
            f"{int(ds.runs.sum())} runs"
        )
    return {
        "description": "; ".join(parts),
        "batches": [str(b) for b in batches],
        "worlds": {slam: list(ds.worlds) for slam, ds in datasets.items()},
        "target": "per world, the mean over its evaluated runs (any outcome) of the run's mean B "
        "error; success = exploration completed",
    }


def train_model(
    batches: Sequence[Path],
    world_dirs: Sequence[Path],
    *,
    command: str = "",
    params: TrainParams = TrainParams(),
    allow_outside: bool = False,
) -> dict[str, Any]:
    """The model file's JSON data from the batch output folders `batches`."""
    rows = read_runs(batches)
    datasets = build_datasets(rows, feature_source(world_dirs, allow_outside=allow_outside))
    model: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": command,
        "features": list(numeric_names()),
        "feature_params": dataclasses.asdict(FeatureParams()),
        "train_params": dataclasses.asdict(params),
        "training": describe(datasets, batches),
        "slam": {},
    }
    for slam, ds in sorted(datasets.items()):
        if len(ds.worlds) < 2:
            raise InputError(f"{slam}: only {len(ds.worlds)} evaluated world, need at least 2")
        part = fit_slam(ds, params)
        cvs = cross_validate(ds, params)
        part["cv"] = cv_summary(cvs)
        # the quantile trees' 10-90 % interval held too few held-out worlds (they fit the
        # training worlds' spread): widen it by the conformal margin of the held-out scores
        for target, cv in cvs.items():
            part["targets"][target]["interval_margin"] = conformal_margin(cv.conformity(), INTERVAL)
        model["slam"][slam] = part
    return model
