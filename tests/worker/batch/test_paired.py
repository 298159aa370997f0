"""The paired comparison: a hand-derived interval, scipy's paired t-test as the reference,
seeds paired and unpaired, and its table in a batch's report.html."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from tests.summaries import make_summary, relation
from tests.summaries import stats as rel_stats
from tests.worker.batch.test_html import _Page
from worker.batch.experiment import RunSpec
from worker.batch.html import write_html
from worker.batch.paired import Sample, batch_paired_rows, mean_ci, paired_diffs
from worker.batch.state import record_of


def test_hand_derived_interval_of_three_differences():
    # d = 1, 2, 3: mean 2, sample std 1, standard error 1 / sqrt(3); Student's t with 2
    # degrees of freedom has the closed-form quantile t_p = (2p - 1) / sqrt(2 p (1 - p)),
    # 4.3027 at p = 0.975 (the tables' value)
    mean, lo, hi = mean_ci([1.0, 2.0, 3.0])
    t975 = 0.95 / math.sqrt(2 * 0.975 * 0.025)
    assert t975 == pytest.approx(4.3027, abs=1e-4)
    half = t975 / math.sqrt(3.0)
    assert mean == 2.0
    assert lo == pytest.approx(2.0 - half, rel=1e-12)
    assert hi == pytest.approx(2.0 + half, rel=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("confidence", [0.9, 0.95, 0.99])
def test_interval_is_scipys_paired_t_test_interval(seed, confidence):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 12))
    a = rng.gamma(2.0, 0.05, n)
    b = a + rng.normal(0.02, 0.03, n)
    samples = [Sample("w", "graph", s, float(a[s])) for s in range(n)]
    samples += [Sample("w", "rbpf", s, float(b[s])) for s in range(n)]
    (d,) = paired_diffs(samples, confidence)
    ref = stats.ttest_rel(a, b).confidence_interval(confidence)
    assert (d.a, d.b, d.n) == ("graph", "rbpf", n)
    assert d.mean_diff == pytest.approx(float(np.mean(a - b)), abs=1e-15)
    assert d.ci_low == pytest.approx(ref.low, rel=1e-9)
    assert d.ci_high == pytest.approx(ref.high, rel=1e-9)
    assert d.a_lower == int(np.sum(a < b))


def test_only_common_seeds_are_paired_and_groups_kept_apart():
    samples = [
        Sample("office", "rbpf", 1, 0.30), Sample("office", "rbpf", 2, 0.50),
        Sample("office", "rbpf", 3, 0.90),  # no graph run on seed 3: left out
        Sample("office", "graph", 1, 0.10), Sample("office", "graph", 2, 0.20),
        Sample("office", "graph", 4, 0.05),  # no rbpf run on seed 4: left out
        Sample("house", "graph", 1, 0.40), Sample("house", "rbpf", 1, 0.20),
        Sample("house", "odometry", 2, 3.0),  # no common seed with the others
    ]  # fmt: skip
    diffs = paired_diffs(samples)
    (office,) = [d for d in diffs if d.group == "office"]
    house = [d for d in diffs if d.group == "house"]
    assert office.seeds == (1, 2)
    # differences -0.2 and -0.3: mean -0.25, std 0.0707, t_{0.975, 1} = 12.7062
    assert office.mean_diff == pytest.approx(-0.25)
    assert office.ci_high - office.mean_diff == pytest.approx(12.706204736 * 0.05, rel=1e-8)
    assert office.verdict == "no clear difference" and office.a_lower == 2
    assert len(house) == 1 and house[0].n == 1 and house[0].ci_low is None
    assert house[0].verdict == "one pair: no interval"
    assert house[0].mean_diff == pytest.approx(0.2)
    # pooled over both worlds: (office, 1), (office, 2), (house, 1): -0.2, -0.3, +0.2
    (pooled,) = [d for d in diffs if d.group == "ALL"]
    assert pooled.seeds == (("house", 1), ("office", 1), ("office", 2))
    assert pooled.as_row()["seeds"] == "house:1 office:1 office:2"
    ref = stats.ttest_rel([0.40, 0.10, 0.20], [0.20, 0.30, 0.50]).confidence_interval(0.95)
    assert pooled.mean_diff == pytest.approx(-0.1)
    assert (pooled.ci_low, pooled.ci_high) == (pytest.approx(ref.low), pytest.approx(ref.high))
    assert diffs[-1] is pooled  # after the per-world rows


def test_verdict_names_the_lower_algorithm_when_the_interval_excludes_zero():
    samples = [Sample("w", "graph", s, 0.1 + 0.01 * s) for s in range(5)]
    samples += [Sample("w", "rbpf", s, 0.3 + 0.012 * s) for s in range(5)]
    (d,) = paired_diffs(samples)
    assert d.ci_high < 0 and d.verdict == "graph lower"
    swapped = [Sample(s.group, {"graph": "rbpf", "rbpf": "graph"}[s.slam], s.seed, s.value)
               for s in samples]  # fmt: skip
    (e,) = paired_diffs(swapped)
    assert e.ci_low > 0 and e.verdict == "rbpf lower"


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="at least one pair"):
        mean_ci([])
    with pytest.raises(ValueError, match="confidence"):
        mean_ci([1.0, 2.0], confidence=1.0)


def _spec(world: str, slam: str, seed: int) -> RunSpec:
    return RunSpec(f"{world}{slam}{seed}", f"/w/{world}.yaml", world, world, "no_furniture",
                   slam, 0.0, seed, {})  # fmt: skip


def _done(b_mean: float):
    b = relation(rel_stats(b_mean, 0.1, 100), rel_stats(0.01, 0.005, 100))
    return make_summary(outcome="completed", reason=None, stop="no_frontier", coverage=0.9,
                        relations={"B": b})  # fmt: skip


def test_batch_report_holds_the_paired_table(tmp_path):
    crash = make_summary(outcome="failed", reason="collision", stop="collision",
                         coverage=0.2, relations={})  # fmt: skip
    recs = [
        record_of(_spec("office", "graph", 1), summary=_done(0.10)),
        record_of(_spec("office", "graph", 2), summary=_done(0.20)),
        record_of(_spec("office", "graph", 3), summary=crash),  # failed: not paired
        record_of(_spec("office", "rbpf", 1), summary=_done(0.40)),
        record_of(_spec("office", "rbpf", 2), summary=_done(0.60)),
        record_of(_spec("office", "rbpf", 3), summary=_done(0.50)),
    ]
    rows = batch_paired_rows(recs)
    assert [(r["group"], r["a"], r["b"], r["seeds"]) for r in rows] == [
        ("office", "graph", "rbpf", "1 2")
    ]
    page = _Page()
    page.feed(write_html(recs, {}, tmp_path, {}, expected=6).read_text())
    assert page.balanced
    (table,) = [t for t in page.tables if t and t[0][:3] == ["world", "A", "B"]]
    # differences -0.3, -0.4: mean -0.35, half width 12.7062 * 0.05 = 0.6353
    assert table[1][:7] == ["office", "graph", "rbpf", "2", "0.1500", "0.5000", "-0.3500"]
    assert table[1][7:9] == ["-0.9853", "0.2853"]
    assert table[1][9:] == ["2 of 2", "no clear difference"]
