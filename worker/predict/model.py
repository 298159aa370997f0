"""The map-quality model file (JSON, no pickle) and predictions from it: mean B errors with an
80 % interval, the probability that exploration completes, and the features behind them."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from worker.errors import InputError
from worker.predict.trees import predict_gbr
from worker.world.features import WorldFeatures

FORMAT = "mapqual-map-quality-model"
VERSION = 1
BUNDLED = Path(__file__).with_name("bundled_model.json")
TARGETS = (("b_mean_t", "m"), ("b_mean_r", "rad"))


def load_model(path: str | Path | None = None) -> dict[str, Any]:
    """The model in `path` (default: the bundled one), checked for its format and version."""
    path = Path(path) if path is not None else BUNDLED
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"cannot read the model: {exc.strerror}", path=path) from None
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError("not a JSON model file", path=path) from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise InputError(f"not a {FORMAT} file", path=path)
    if data.get("version") != VERSION:
        raise InputError(
            f"model format version {data.get('version')!r}, this mapqual reads version "
            f"{VERSION} (retrain with `mapqual predict train`)",
            path=path,
        )
    return data


def linear_predict(lin: dict[str, Any], x: np.ndarray) -> tuple[float, np.ndarray]:
    """(prediction, per-feature contributions `(F,)`) of a standardised linear model."""
    z = (x - np.asarray(lin["mean"])) / np.asarray(lin["scale"])
    contrib = np.asarray(lin["coef"]) * z
    return float(lin["intercept"] + contrib.sum()), contrib


def _untransform(v: float, transform: str) -> float:
    return math.exp(v) if transform == "log" else v


@dataclass(frozen=True)
class TargetPrediction:
    """One predicted quantity [its unit]: the boosted trees' median and 80 % interval, and the
    linear baseline's value."""

    unit: str
    median: float
    low: float  # 10 % quantile, widened by the conformal margin (80 % held-out coverage)
    high: float  # 90 % quantile, likewise
    linear: float
    drivers: tuple[tuple[str, float], ...]  # (feature, contribution to log error), largest first


@dataclass(frozen=True)
class Prediction:
    """What the model says of one floorplan for one SLAM algorithm."""

    slam: str
    b_mean_t: TargetPrediction
    b_mean_r: TargetPrediction
    success_probability: float
    trained_on: str  # the training set's one-line description
    features: dict[str, Any]

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        from dataclasses import asdict

        d = asdict(self)
        for k, _ in TARGETS:
            d[k]["drivers"] = [{"feature": n, "contribution": c} for n, c in d[k]["drivers"]]
        return d


def _target(spec: dict[str, Any], x: np.ndarray, names: list[str], unit: str) -> TargetPrediction:
    tf = spec.get("transform", "none")
    lin, contrib = linear_predict(spec["linear"], x)
    q = sorted(
        float(predict_gbr(spec["quantiles"][k], x[None, :])[0]) for k in ("0.1", "0.5", "0.9")
    )
    order = np.argsort(-np.abs(contrib))[:3]
    # the interval's conformal margin (absent from models trained before it: 0); a negative
    # one narrows the interval, never past the median
    m = float(spec.get("interval_margin", 0.0))
    return TargetPrediction(
        unit=unit,
        median=_untransform(q[1], tf),
        low=_untransform(min(q[0] - m, q[1]), tf),
        high=_untransform(max(q[2] + m, q[1]), tf),
        linear=_untransform(lin, tf),
        drivers=tuple((names[i], float(contrib[i])) for i in order),
    )


def _success(spec: dict[str, Any], x: np.ndarray) -> float:
    if spec["kind"] == "constant":
        return float(spec["probability"])
    logit, _ = linear_predict(spec, x)
    return 1.0 / (1.0 + math.exp(-logit))


def predict(model: dict[str, Any], features: WorldFeatures, slam: str = "rbpf") -> Prediction:
    """Predict with `model` (from `load_model`) for a world's `features`."""
    per_slam = model.get("slam", {})
    if slam not in per_slam:
        have = ", ".join(sorted(per_slam)) or "none"
        raise InputError(f"the model has no {slam!r} part (it has: {have})")
    names = list(model["features"])
    d = features.as_dict()
    missing = [n for n in names if n not in d]
    if missing:
        raise InputError(f"the model reads features this mapqual does not compute: {missing}")
    x = np.array([float(d[n]) for n in names])
    part = per_slam[slam]
    return Prediction(
        slam=slam,
        b_mean_t=_target(part["targets"]["b_mean_t"], x, names, "m"),
        b_mean_r=_target(part["targets"]["b_mean_r"], x, names, "rad"),
        success_probability=_success(part["success"], x),
        trained_on=str(model.get("training", {}).get("description", "")),
        features=d,
    )
