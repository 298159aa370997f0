"""Paired comparison of SLAM algorithms: on the same worlds and seeds, the per-seed difference
of mean B translational error and its t-based confidence interval.

Two algorithms run on one world with one seed see the same world, start and sensor noise draw
(the seed fixes the simulator), so their errors are paired: the difference d_s = e_A(s) - e_B(s)
per seed s takes out the seed-to-seed spread both share. Over the n seeds where both runs
completed with B relations, the mean difference has the confidence interval

    mean(d) +- t_{(1 + c) / 2, n - 1} * std(d, ddof=1) / sqrt(n)

(Student's t, c = 0.95 by default), the interval of the paired t-test; with one pair there is
no interval. A negative difference means A's error is the lower.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from itertools import combinations
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import stats

if TYPE_CHECKING:
    from worker.batch.records import BatchRecord

CONFIDENCE = 0.95  # [1] of the intervals
ALL = "ALL"  # the group of the pooled rows


@dataclass(frozen=True)
class Sample:
    """One completed run's score: its group (world and any variant / noise label), the
    algorithm, the seed and the mean B translational error [m]."""

    group: str
    slam: str
    seed: int
    value: float  # [m]


@dataclass(frozen=True)
class PairedDiff:
    """A against B on one group, over the seeds where both have a score."""

    group: str
    a: str
    b: str
    seeds: tuple  # the paired seeds (the ALL rows: (group, seed) pairs)
    mean_a: float  # [m] mean over the paired seeds
    mean_b: float  # [m]
    mean_diff: float  # [m] mean of e_A - e_B
    std_diff: float | None  # [m] sample std (ddof 1) of the differences; None for one pair
    ci_low: float | None  # [m] the confidence interval of mean_diff; None for one pair
    ci_high: float | None
    a_lower: int  # seeds where A's error is the lower
    confidence: float = CONFIDENCE

    @property
    def n(self) -> int:
        """Paired seeds."""
        return len(self.seeds)

    @property
    def verdict(self) -> str:
        """Which error is the lower at this confidence, or that the interval holds zero."""
        if self.ci_low is None or self.ci_high is None:
            return "one pair: no interval"
        if self.ci_high < 0:
            return f"{self.a} lower"
        if self.ci_low > 0:
            return f"{self.b} lower"
        return "no clear difference"

    def as_row(self) -> dict[str, Any]:
        """A table row (report, dashboard): the fields, n and the verdict."""
        return {
            "group": self.group, "a": self.a, "b": self.b, "n": self.n,
            "seeds": " ".join(_key(s) for s in self.seeds), "mean_a": self.mean_a,
            "mean_b": self.mean_b, "mean_diff": self.mean_diff, "std_diff": self.std_diff,
            "ci_low": self.ci_low, "ci_high": self.ci_high, "a_lower": self.a_lower,
            "confidence": self.confidence, "verdict": self.verdict,
        }  # fmt: skip


def _key(seed) -> str:
    return f"{seed[0]}:{seed[1]}" if isinstance(seed, tuple) else str(seed)


def mean_ci(
    diffs: Sequence[float], confidence: float = CONFIDENCE
) -> tuple[float, float | None, float | None]:
    """(mean, low, high) of the differences: the t-based interval; (mean, None, None) for one."""
    d = np.asarray(diffs, dtype=np.float64)
    if d.size == 0:
        raise ValueError("a paired comparison needs at least one pair")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence must be in (0, 1), got {confidence}")
    mean = float(d.mean())
    if d.size < 2:
        return mean, None, None
    half = float(stats.t.ppf(0.5 + 0.5 * confidence, d.size - 1)) * float(d.std(ddof=1))
    half /= math.sqrt(d.size)
    return mean, mean - half, mean + half


def compare(a: str, b: str, group: str, by_seed: dict[str, dict], confidence: float):
    """A against B on one group, over the seed keys both have (None when none)."""
    seeds = tuple(sorted(set(by_seed[a]) & set(by_seed[b])))
    if not seeds:
        return None
    ea = np.array([by_seed[a][s] for s in seeds])
    eb = np.array([by_seed[b][s] for s in seeds])
    mean, lo, hi = mean_ci(ea - eb, confidence)
    std = float(np.std(ea - eb, ddof=1)) if len(seeds) > 1 else None
    return PairedDiff(
        group, a, b, seeds, float(ea.mean()), float(eb.mean()), mean, std, lo, hi,
        int(np.sum(ea < eb)), confidence,
    )  # fmt: skip


def paired_diffs(samples: Iterable[Sample], confidence: float = CONFIDENCE) -> list[PairedDiff]:
    """Every pair of algorithms (in name order, A before B) on every group, over their
    common seeds; several scores of one group, algorithm and seed are averaged first. When
    a pair of algorithms meets on more than one group, a last row ALL pairs them over every
    (group, seed) they share: "A is lower across these worlds", with its interval."""
    acc: dict[str, dict[str, dict[int, list[float]]]] = defaultdict(
        lambda: defaultdict(lambda: defaultdict(list))
    )
    for s in samples:
        if s.value is not None and math.isfinite(s.value):
            acc[s.group][s.slam][int(s.seed)].append(float(s.value))
    out: list[PairedDiff] = []
    for group in sorted(acc):
        by_seed = {
            alg: {seed: float(np.mean(v)) for seed, v in per.items()}
            for alg, per in acc[group].items()
        }
        for a, b in combinations(sorted(by_seed), 2):
            diff = compare(a, b, group, by_seed, confidence)
            if diff is not None:
                out.append(diff)
    return out + _pooled(acc, out, confidence)


def _pooled(acc, per_group: list[PairedDiff], confidence: float) -> list[PairedDiff]:
    """The ALL rows: each pair of algorithms over the (group, seed) keys they share."""
    rows = []
    for a, b in sorted({(d.a, d.b) for d in per_group}):
        if sum(d.a == a and d.b == b for d in per_group) < 2:
            continue
        by_key = {
            alg: {(g, seed): float(np.mean(v)) for g in acc for seed, v in acc[g][alg].items()}
            for alg in (a, b)
        }
        diff = compare(a, b, ALL, by_key, confidence)
        if diff is not None:
            rows.append(diff)
    return rows


def group_label(world: str, noise: float | None = None) -> str:
    """The group of a batch run: its world (which names its furniture variant), with a
    non-zero laser noise."""
    return f"{world}, noise {noise:g} m" if noise else world


def batch_samples(records: Iterable[BatchRecord]) -> list[Sample]:
    """The scores of a batch's completed runs with B relations (its records as the report
    reads them)."""
    from worker.batch.records import outcome_of, relation_stats
    from worker.status import RunOutcome

    out = []
    for r in records:
        b = relation_stats(r)
        if outcome_of(r)[0] != RunOutcome.COMPLETED or b is None or b.translation.n == 0:
            continue
        group = group_label(r["world"], r.get("noise"))
        out.append(Sample(group, r["slam"], int(r["seed"]), float(b.translation.mean)))
    return out


def batch_paired_rows(records: Iterable[BatchRecord]) -> list[dict[str, Any]]:
    """The paired comparison of a batch as table rows (empty with one algorithm)."""
    return [d.as_row() for d in paired_diffs(batch_samples(records))]
