"""The 95 % half-width beside every relation mean: against scipy.stats and a t table."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import stats

from worker.evaluate.metric import evaluate_relations, mean_half_width
from worker.evaluate.relations import Relations
from worker.evaluate.trajectory import Trajectory


def test_errors_1_2_3_by_hand_from_a_t_table():
    # mean 2, sample std 1, t(0.975, 2 dof) = 4.303 (printed t tables): 4.303 / sqrt(3)
    assert mean_half_width(np.array([1.0, 2.0, 3.0])) == pytest.approx(4.303 / 3**0.5, abs=1e-3)
    # 30 errors alternating 0 and 1: mean 0.5, s^2 = 30 * 0.25 / 29; t(0.975, 29) = 2.045
    err = np.tile([0.0, 1.0], 15)
    s = (7.5 / 29) ** 0.5
    assert mean_half_width(err) == pytest.approx(2.045 * s / 30**0.5, rel=1e-3)


@pytest.mark.parametrize("n", [2, 7, 40, 5000])
def test_half_width_is_scipys_t_interval(n):
    err = np.random.default_rng(n).gamma(2.0, 0.1, n)
    lo, hi = stats.t.interval(0.95, n - 1, loc=err.mean(), scale=stats.sem(err))
    assert mean_half_width(err) == pytest.approx((hi - lo) / 2, rel=1e-10)
    assert mean_half_width(err) == pytest.approx(
        stats.t.ppf(0.975, n - 1) * err.std(ddof=1) / n**0.5, rel=1e-10
    )
    assert mean_half_width(err, 0.99) > mean_half_width(err)


def test_the_interval_covers_the_true_mean_95_times_in_100():
    rng = np.random.default_rng(3)
    draws = rng.normal(0.4, 0.2, (4000, 12))
    hits = [abs(d.mean() - 0.4) <= mean_half_width(d) for d in draws]
    # binomial(4000, 0.95): std 0.0034, so 0.95 +- 0.012 is four standard deviations
    assert np.mean(hits) == pytest.approx(0.95, abs=0.012)


def test_below_two_errors_there_is_no_interval():
    assert mean_half_width(np.zeros(0)) is None and mean_half_width(np.ones(1)) is None
    assert mean_half_width(np.ones(5)) == 0.0


def test_the_relation_summary_carries_it_on_both_axes():
    est = Trajectory(np.array([0.0, 1.0, 2.0, 3.0]), np.zeros((4, 3)))
    # true motions of 1, 2 and 3 m against an estimate that stands still: errors 1, 2, 3
    rel = Relations([0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [[1, 0, 0.1], [2, 0, 0.2], [3, 0, 0.3]])
    s = evaluate_relations(rel, est).summary()
    assert s["translation"]["ci95"] == pytest.approx(4.303 / 3**0.5, abs=1e-3)
    assert s["rotation"]["ci95"] == pytest.approx(0.4303 / 3**0.5, abs=1e-4)
    one = evaluate_relations(Relations([0.0], [1.0], [[1, 0, 0]]), est).summary()
    assert one["translation"]["ci95"] is None
    assert '"ci95": null' in json.dumps(one, allow_nan=False)
