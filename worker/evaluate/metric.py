"""The relations metric (Kuemmerle et al. 2009): per-relation errors of an estimate, summary."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.special import stdtrit

from worker.evaluate.lookup_kernels import TIME_TOL_S, relation_errors
from worker.evaluate.relations import Relations
from worker.evaluate.trajectory import DEFAULT_MAX_GAP_S, Trajectory

CONFIDENCE = 0.95  # two-sided level of the half-width printed beside every relation mean


def mean_half_width(err: NDArray[np.float64], confidence: float = CONFIDENCE) -> float | None:
    """Half-width of the t-based two-sided `confidence` interval of the mean of `err` (n,):
    t_{(1+c)/2, n-1} s / sqrt(n), s the sample std (ddof 1); None below 2 errors.

    It treats the relations as independent draws, which random B pairs are; consecutive
    relations (A, S, M) overlap in time, so theirs is a lower bound on the true uncertainty.
    """
    n = int(err.shape[0])
    if n < 2:
        return None
    t = float(stdtrit(n - 1, 0.5 + 0.5 * confidence))
    return t * float(np.std(err, ddof=1)) / float(np.sqrt(n))


def error_stats(err: NDArray[np.float64]) -> dict[str, float | int | None]:
    """mean, std, min, max, n and mean of squares of the errors `(n,)`.

    std is the population std (ddof 0): the spread of the errors of this very set of
    relations, as evo and Kuemmerle's evaluator report it, and defined for n = 1. With no
    error at all the statistics are None (JSON null: JSON has no NaN).
    """
    n = int(err.shape[0])
    if n == 0:
        return {"mean": None, "std": None, "min": None, "max": None, "n": 0, "mean_squared": None}
    return {
        "mean": float(np.mean(err)),
        "std": float(np.std(err)),
        "min": float(np.min(err)),
        "max": float(np.max(err)),
        "n": n,
        "mean_squared": float(np.mean(err * err)),
    }


@dataclass(frozen=True)
class RelationErrors:
    """Errors of an estimate on each relation.

    t1, t2: (M,) [s] the relation's timestamps.
    translation: (M,) [m] |d.xy - d*.xy|; rotation: (M,) [rad] |wrap(d.theta - d*.theta)|.
    evaluated: (M,) bool, False where a pose could not be looked up (errors there are 0
        and excluded from every statistic).
    """

    t1: NDArray[np.float64]
    t2: NDArray[np.float64]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    evaluated: NDArray[np.bool_]

    @property
    def skipped(self) -> int:
        """Relations whose poses the estimate could not provide."""
        return int(self.evaluated.shape[0] - np.count_nonzero(self.evaluated))

    def summary(self) -> dict[str, Any]:
        """`{"translation": {mean, std, min, max, n, mean_squared, ci95}, "rotation": {...},
        "skipped": int}` over the evaluated relations (metres, radians); ci95 is the 95 %
        half-width of the mean (`mean_half_width`), None below 2 relations."""
        ok = self.evaluated
        out: dict[str, Any] = {}
        for axis, err in (("translation", self.translation[ok]), ("rotation", self.rotation[ok])):
            out[axis] = {**error_stats(err), "ci95": mean_half_width(err)}
        out["skipped"] = self.skipped
        return out


def evaluate_relations(
    rel: Relations, est: Trajectory, max_gap: float = DEFAULT_MAX_GAP_S
) -> RelationErrors:
    """Errors of the estimate on every relation: X1, X2 the estimate at t1, t2 (exact sample
    or interpolation between neighbours within max_gap [s]), d = inv(X1) X2, translational
    error |d.xy - d*.xy| and rotational |wrap(d.theta - d*.theta)|, i.e. the norms of
    inv(d*) d (SPEC, Evaluation)."""
    err_t, err_r, ok = relation_errors(
        est.packed, rel.t1, rel.t2, rel.delta, float(max_gap), TIME_TOL_S
    )
    return RelationErrors(rel.t1, rel.t2, err_t, err_r, ok)
