"""Fit the map-quality models per SLAM algorithm (scikit-learn): ridge regression on the
standardised features (the interpretable baseline), gradient boosting with quantile loss for
the 10/50/90 % quantiles, logistic regression for the probability of a completed run."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from worker.predict.dataset import Dataset
from worker.predict.trees import export_gbr


@dataclass(frozen=True)
class TrainParams:
    """Model settings (small data: a few dozen worlds)."""

    ridge_alphas: tuple[float, ...] = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)  # [-] on z-scores
    trees: int = 150  # boosting stages
    depth: int = 2  # tree depth
    learning_rate: float = 0.05  # [-]
    min_leaf: int = 3  # [worlds] per leaf
    logistic_c: float = 1.0  # [-] inverse L2 strength
    seed: int = 0


def _standardise(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column means and scales (1 for a constant column)."""
    mean = X.mean(axis=0)
    scale = X.std(axis=0)
    return mean, np.where(scale > 1e-12, scale, 1.0)


def fit_linear(X: np.ndarray, y: np.ndarray, p: TrainParams) -> dict[str, Any]:
    """Ridge on z-scored features, alpha by (generalised) leave-one-out CV; JSON data."""
    from sklearn.linear_model import RidgeCV

    mean, scale = _standardise(X)
    model = RidgeCV(alphas=list(p.ridge_alphas)).fit((X - mean) / scale, y)
    return {
        "mean": mean.tolist(),
        "scale": scale.tolist(),
        "coef": [float(c) for c in model.coef_],
        "intercept": float(model.intercept_),
        "alpha": float(model.alpha_),
    }


def fit_quantiles(X: np.ndarray, y: np.ndarray, p: TrainParams) -> dict[str, Any]:
    """Gradient boosting, quantile loss at 10, 50 and 90 %: exported trees and the median
    model's impurity importances."""
    from sklearn.ensemble import GradientBoostingRegressor

    out: dict[str, Any] = {}
    importances = None
    for q in (0.1, 0.5, 0.9):
        model = GradientBoostingRegressor(
            loss="quantile",
            alpha=q,
            n_estimators=p.trees,
            max_depth=p.depth,
            learning_rate=p.learning_rate,
            min_samples_leaf=min(p.min_leaf, max(1, len(y) // 4)),
            random_state=p.seed,
        ).fit(X, y)
        out[f"{q:g}"] = export_gbr(model)
        if q == 0.5:
            importances = model.feature_importances_
    return {"quantiles": out, "importances": importances}


def fit_success(X: np.ndarray, completed: np.ndarray, runs: np.ndarray, p: TrainParams):
    """Logistic regression of completion on z-scored features, each world's runs as weighted
    0/1 rows; a constant (Laplace-smoothed rate) when every run ended the same way."""
    from sklearn.linear_model import LogisticRegression

    rate = (completed.sum() + 1.0) / (runs.sum() + 2.0)
    if completed.sum() == 0 or completed.sum() == runs.sum():
        return {"kind": "constant", "probability": float(rate)}
    mean, scale = _standardise(X)
    Z = (X - mean) / scale
    Zr = np.concatenate([Z, Z])
    yr = np.concatenate([np.ones(len(Z)), np.zeros(len(Z))])
    w = np.concatenate([completed, runs - completed]).astype(np.float64)
    keep = w > 0
    model = LogisticRegression(C=p.logistic_c).fit(Zr[keep], yr[keep], sample_weight=w[keep])
    return {
        "kind": "logistic",
        "mean": mean.tolist(),
        "scale": scale.tolist(),
        "coef": [float(c) for c in model.coef_[0]],
        "intercept": float(model.intercept_[0]),
    }


def _importances(names, lin: dict[str, Any], gbm: np.ndarray) -> dict[str, Any]:
    """Per feature: |standardised ridge coefficient| and boosted-tree importance, each summing
    to 1 over the features, sorted by the trees'."""
    coef = np.abs(np.asarray(lin["coef"]))
    lin_share = coef / coef.sum() if coef.sum() > 0 else coef
    order = np.argsort(-gbm)
    return {names[i]: {"trees": float(gbm[i]), "linear": float(lin_share[i])} for i in order}


def fit_target(X: np.ndarray, y: np.ndarray, names, p: TrainParams) -> dict[str, Any]:
    """Models of log(error): errors are positive and spread over orders of magnitude, and
    quantiles commute with the log."""
    ylog = np.log(np.maximum(y, 1e-6))
    lin = fit_linear(X, ylog, p)
    gbm = fit_quantiles(X, ylog, p)
    return {
        "transform": "log",
        "linear": lin,
        "quantiles": gbm["quantiles"],
        "importances": _importances(names, lin, gbm["importances"]),
    }


def fit_slam(ds: Dataset, p: TrainParams = TrainParams()) -> dict[str, Any]:
    """The model part of one SLAM algorithm (JSON data)."""
    return {
        "worlds": len(ds.worlds),
        "buildings": len(set(ds.buildings)),
        "runs": int(ds.runs.sum()),
        "targets": {
            "b_mean_t": fit_target(ds.X, ds.b_mean_t, ds.names, p),
            "b_mean_r": fit_target(ds.X, ds.b_mean_r, ds.names, p),
        },
        "success": fit_success(ds.X, ds.completed, ds.runs, p),
    }


def log_safe(v: float) -> float:
    """log of a positive error, floored at 1e-6."""
    return math.log(max(v, 1e-6))
