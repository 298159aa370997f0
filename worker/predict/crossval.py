"""Leave-one-building-out cross-validation of the map-quality models (a building's furnished
variant is held out with it), against predicting the training mean and a free-area-only model."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from worker.predict.dataset import Dataset
from worker.predict.model import linear_predict
from worker.predict.train import TrainParams, fit_linear, fit_quantiles
from worker.predict.trees import predict_gbr

METHODS = ("trees", "linear", "mean", "free_area")
INTERVAL = 0.8  # the predicted interval's nominal coverage


@dataclass(frozen=True)
class CvResult:
    """Held-out predictions `(N,)` [the target's unit] per method, and the measured values."""

    target: str
    worlds: tuple[str, ...]
    buildings: tuple[str, ...]
    measured: np.ndarray
    predicted: dict[str, np.ndarray]
    low: np.ndarray  # trees' 10 % quantile
    high: np.ndarray  # trees' 90 % quantile

    def conformity(self) -> np.ndarray:
        """`(N,)` [log units] how far each measured value lies outside its held-out 10-90 %
        interval (negative: inside), the score of conformalised quantile regression (Romano,
        Patterson and Candes 2019), on the log scale the models are fitted on."""
        y = np.log(np.maximum(self.measured, 1e-6))
        return np.maximum(np.log(self.low) - y, y - np.log(self.high))

    def calibrated_bounds(self, level: float = INTERVAL) -> tuple[np.ndarray, np.ndarray]:
        """`(N,)` each world's interval widened by the margin that the *other* buildings'
        held-out scores give (so no world calibrates its own interval)."""
        e, b = self.conformity(), np.array(self.buildings)
        margin = np.array([conformal_margin(e[b != g], level) for g in self.buildings])
        return self.low * np.exp(-margin), self.high * np.exp(margin)

    def scores(self) -> dict[str, dict[str, float]]:
        """Per method: Spearman over worlds and over buildings (variants averaged), MAE."""
        out = {}
        for m, pred in self.predicted.items():
            out[m] = {
                "spearman_worlds": spearman(pred, self.measured),
                "spearman_buildings": spearman(*self._by_building(pred)),
                "mae": float(np.mean(np.abs(pred - self.measured))),
            }
        inside = (self.measured >= self.low) & (self.measured <= self.high)
        out["trees"]["interval_coverage"] = float(inside.mean())
        lo, hi = self.calibrated_bounds()
        inside = (self.measured >= lo) & (self.measured <= hi)
        out["trees"]["calibrated_interval_coverage"] = float(inside.mean())
        return out

    def _by_building(self, pred: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        names = sorted(set(self.buildings))
        b = np.array(self.buildings)
        return (
            np.array([pred[b == n].mean() for n in names]),
            np.array([self.measured[b == n].mean() for n in names]),
        )


def conformal_margin(scores: np.ndarray, level: float = INTERVAL) -> float:
    """The split-conformal margin: the ceil((n + 1) level)-th smallest of n scores (the
    largest when that rank passes n), so that a new world's interval widened by it holds its
    value with probability at least `level` when worlds are exchangeable; 0 without scores."""
    s = np.sort(np.asarray(scores, dtype=float))
    if s.size == 0:
        return 0.0
    k = min(math.ceil((s.size + 1) * level), s.size)
    return float(s[k - 1])


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation (scipy); nan for fewer than 3 points or a constant side."""
    from scipy.stats import spearmanr

    if len(a) < 3 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return math.nan
    return float(spearmanr(a, b).statistic)


def _fold(ds: Dataset, y: np.ndarray, train: np.ndarray, test: np.ndarray, p: TrainParams):
    """Predictions of each method for the `test` rows, fitted on the `train` rows."""
    X, ylog = ds.X, np.log(np.maximum(y, 1e-6))
    lin = fit_linear(X[train], ylog[train], p)
    quant = fit_quantiles(X[train], ylog[train], p)["quantiles"]
    area_col = ds.names.index("free_area_m2")
    area = fit_linear(X[train][:, [area_col]], ylog[train], TrainParams(ridge_alphas=(1e-6,)))
    # the three quantile models sorted per world, as `predict` does (they may cross)
    q = np.sort([np.exp(predict_gbr(quant[k], X[test])) for k in ("0.1", "0.5", "0.9")], axis=0)
    out = {
        "trees": q[1],
        "linear": np.exp([linear_predict(lin, x)[0] for x in X[test]]),
        "mean": np.full(test.sum(), y[train].mean()),
        "free_area": np.exp([linear_predict(area, x)[0] for x in X[test][:, [area_col]]]),
    }
    return out, q[0], q[2]


def leave_one_building_out(
    ds: Dataset, target: str = "b_mean_t", p: TrainParams = TrainParams()
) -> CvResult:
    """Hold out each building (with its furnished variant) in turn; predict it from the rest."""
    y = getattr(ds, target)
    groups = np.array(ds.buildings)
    pred = {m: np.full(len(y), np.nan) for m in METHODS}
    low, high = np.full(len(y), np.nan), np.full(len(y), np.nan)
    for g in sorted(set(ds.buildings)):
        test = groups == g
        if test.all():
            continue
        out, lo, hi = _fold(ds, y, ~test, test, p)
        for m in METHODS:
            pred[m][test] = out[m]
        low[test], high[test] = lo, hi
    return CvResult(target, ds.worlds, ds.buildings, y, pred, low, high)


def cross_validate(ds: Dataset, p: TrainParams = TrainParams()) -> dict[str, CvResult]:
    """Leave-one-building-out results of both targets; empty below 3 buildings."""
    if len(set(ds.buildings)) < 3:
        return {}
    return {t: leave_one_building_out(ds, t, p) for t in ("b_mean_t", "b_mean_r")}


def cv_summary(cvs: dict[str, CvResult]) -> dict[str, Any]:
    """Cross-validated scores of both targets (what the model file stores)."""
    if not cvs:
        return {"note": "fewer than 3 buildings: no cross-validation"}
    return {t: cv.scores() for t, cv in cvs.items()}
