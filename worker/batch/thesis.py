"""The thesis side by side: its Tables 6.3-6.5 (thesis_tables.json) beside a batch's figures,
and whether its findings (furniture, noise, A relations) hold on the batch's runs."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import mannwhitneyu

from worker.batch.records import BatchRecord, is_good, outcome_of, relation_stats
from worker.status import RunOutcome

TABLES = Path(__file__).with_name("thesis_tables.json")
FAR = 2.0  # ours and the thesis's differ "by more than 2x" beyond this ratio
SEPARATES = 0.75  # AUC of A means, good against bad runs, from which A separates them
STATS = ("mean", "std", "max", "n")
THESIS_COLUMNS = (
    "world", "thesis_name", "slam", "runs", "good", "thesis_success",
    *(f"{p}{k}_{a}" for a in "tr" for k in STATS for p in ("", "thesis_")),
    "ratio_t", "far",
)  # fmt: skip


@dataclass(frozen=True)
class ThesisRow:
    """One environment of the thesis: success of 10 (None: not in Table 6.3) and B errors
    (mean, std, min, max, n) of Tables 6.4 [m] and 6.5 [rad] (None: not in them)."""

    success: int | None
    translation: dict[str, float] | None
    rotation: dict[str, float] | None


@cache
def tables() -> dict[str, Any]:
    """thesis_tables.json as data."""
    return json.loads(TABLES.read_text(encoding="utf-8"))


def thesis_name(world: str) -> str:
    """The thesis's name of one of our worlds: lower case, without `_scan`, then aliases."""
    name = world.lower().replace("_scan", "")
    aliases = tables()["names"]["aliases"]
    base = name.removesuffix("_furnitures")
    return aliases.get(base, base) + name[len(base) :]


def thesis_row(world: str) -> ThesisRow | None:
    """The thesis's figures for our world `world` (Tables 6.4 and 6.5 name no furnished
    plan: a furnished world gets its success only); None if the thesis has none."""
    t = tables()["tables"]
    name = thesis_name(world)
    errors = {}
    for axis, table in (("translation", "6.4"), ("rotation", "6.5")):
        row = t[table]["rows"].get(name)
        errors[axis] = None if row is None else dict(zip(t[table]["columns"], row, strict=True))
    success = t["6.3"]["success"].get(name)
    if success is None and errors["translation"] is None:
        return None
    return ThesisRow(success, errors["translation"], errors["rotation"])


def _ours(
    recs: Sequence[BatchRecord], axis: str, completed: bool = True
) -> dict[str, float | None]:
    """Mean, std, max and n of B `axis` averaged over the completed runs (as Tables 6.4, 6.5),
    or with `completed` False over every run with B relations."""
    stats = [
        getattr(b, axis)
        for r in recs
        if (not completed or outcome_of(r)[0] == RunOutcome.COMPLETED) and (b := relation_stats(r))
    ]
    return {k: float(np.mean([getattr(s, k) for s in stats])) if stats else None for k in STATS}


def _by(records: Sequence[BatchRecord], noise: bool = False) -> dict[tuple, list]:
    """Records by (world, slam) or, with `noise`, (world, slam, noise), in first order."""
    groups: dict[tuple, list[BatchRecord]] = {}
    for r in records:
        key = (r["world"], r["slam"], r["noise"]) if noise else (r["world"], r["slam"])
        groups.setdefault(key, []).append(r)
    return groups


def side_by_side(records: Sequence[BatchRecord]) -> list[dict[str, Any]]:
    """Per world (without laser noise) that the thesis has and algorithm: our good runs of
    all, the thesis's successes of 10, and B mean / std / max / N, ours beside the thesis's;
    `ratio_t` is our mean translational error over the thesis's, `far` beyond 2x either way."""
    rows = []
    quiet = [r for r in records if r["noise"] == 0.0]
    for (world, slam), recs in _by(quiet).items():
        th = thesis_row(world)
        if th is None:
            continue
        row: dict[str, Any] = {"world": world, "thesis_name": thesis_name(world), "slam": slam}
        row.update(runs=len(recs), good=sum(is_good(r) for r in recs), thesis_success=th.success)
        for axis, suffix in (("translation", "t"), ("rotation", "r")):
            ours, theirs = _ours(recs, axis), getattr(th, axis) or {}
            for k in STATS:
                row[f"{k}_{suffix}"] = ours[k]
                row[f"thesis_{k}_{suffix}"] = theirs.get(k)
        mine, thesis = row["mean_t"], row["thesis_mean_t"]
        row["ratio_t"] = mine / thesis if mine is not None and thesis else None
        row["far"] = row["ratio_t"] is not None and not 1 / FAR <= row["ratio_t"] <= FAR
        rows.append(row)
    return rows


def _mean_t(recs: Sequence[BatchRecord], completed: bool = True) -> float | None:
    return _ours(recs, "translation", completed)["mean"]


def _finding(claim: str, verdicts: list[bool], evidence: list[str], none: str) -> dict:
    """A claim holds when it does in most of the cases checked; None with no case."""
    if not verdicts:
        return {"claim": claim, "holds": None, "evidence": none}
    holds = 2 * sum(verdicts) > len(verdicts)
    head = f"{sum(verdicts)} of {len(verdicts)}: "
    return {"claim": claim, "holds": holds, "evidence": head + "; ".join(evidence)}


def furniture_finding(records: Sequence[BatchRecord]) -> dict[str, Any]:
    """Thesis 6.3.2: the same plan with furniture has a larger mean B error."""
    pairs: dict[tuple, dict[str, float]] = {}
    quiet = [r for r in records if r["noise"] == 0.0]
    for (_, slam), recs in _by(quiet).items():
        if (m := _mean_t(recs)) is not None:
            pairs.setdefault((recs[0]["base"], slam), {})[recs[0]["variant"]] = m
    verdicts, evidence = [], []
    for (base, _), v in pairs.items():
        if len(v) == 2:
            verdicts.append(v["furniture"] > v["no_furniture"])
            evidence.append(f"{base} {v['no_furniture']:.3f} -> {v['furniture']:.3f} m")
    claim = "furniture raises the error (thesis 6.3.2, Fig. 6.3)"
    return _finding(claim, verdicts, evidence, "no plan with completed runs in both variants")


def noise_findings(records: Sequence[BatchRecord]) -> list[dict[str, Any]]:
    """Thesis 6.3.3: more laser noise, fewer successes and a larger mean B error; the error
    over every run with B relations, as Figs. 6.5 and 6.6 average "the runs" (at 0.3 m the
    thesis had one success in ten)."""
    levels: dict[tuple, dict[float, list]] = {}
    for (world, slam, noise), recs in _by(records, noise=True).items():
        levels.setdefault((world, slam), {})[noise] = recs
    success, error, ev_s, ev_e = [], [], [], []
    for (world, _), by_noise in levels.items():
        if len(by_noise) < 2:
            continue
        lo, hi = min(by_noise), max(by_noise)
        share = {n: sum(is_good(r) for r in by_noise[n]) / len(by_noise[n]) for n in (lo, hi)}
        success.append(share[hi] < share[lo])
        ev_s.append(f"{world} good {share[lo]:.0%} at {lo:g} m, {share[hi]:.0%} at {hi:g} m")
        m_lo, m_hi = _mean_t(by_noise[lo], False), _mean_t(by_noise[hi], False)
        if m_lo is not None and m_hi is not None:
            error.append(m_hi > m_lo)
            ev_e.append(f"{world} {m_lo:.3f} m at {lo:g} m, {m_hi:.3f} m at {hi:g} m")
    none = "no world run at more than one noise level (with B relations at both ends)"
    return [
        _finding("noise lowers success (thesis 6.3.3, Fig. 6.4)", success, ev_s, none),
        _finding("noise raises the error (thesis 6.3.3, Figs. 6.5, 6.6)", error, ev_e, none),
    ]


def auc(bad: Sequence[float], good: Sequence[float]) -> float:
    """P(a bad run's figure > a good run's), ties counting half (Mann-Whitney U / n1 n2)."""
    return float(mannwhitneyu(bad, good).statistic) / (len(bad) * len(good))


def a_finding(records: Sequence[BatchRecord]) -> dict[str, Any]:
    """Thesis 6.2: A relations barely separate good from bad maps. The AUC of the runs' mean A
    error between visually good and bad completed runs (good: B under 1 m and 0.03 rad) is
    below 0.75 when it holds; 0.5 is no separation at all."""
    good: list[float] = []
    bad: list[float] = []
    b_good: list[float] = []
    b_bad: list[float] = []
    for r in records:
        a, b = relation_stats(r, "A"), relation_stats(r)
        if outcome_of(r)[0] != RunOutcome.COMPLETED or a is None or b is None:
            continue
        (good if is_good(r) else bad).append(a.translation.mean)
        (b_good if is_good(r) else b_bad).append(b.translation.mean)
    claim = "A relations barely separate good from bad maps (thesis 6.2)"
    if not good or not bad:
        return {"claim": claim, "holds": None, "evidence": "needs both good and bad runs"}
    a_auc, b_auc = auc(bad, good), auc(b_bad, b_good)
    evidence = (
        f"AUC of mean A error, {len(bad)} bad against {len(good)} good runs: {a_auc:.2f} "
        f"(B: {b_auc:.2f}, which also defines good); median A {np.median(bad):.4f} m bad, "
        f"{np.median(good):.4f} m good"
    )
    return {"claim": claim, "holds": a_auc < SEPARATES, "evidence": evidence}


def findings(records: Sequence[BatchRecord]) -> list[dict[str, Any]]:
    """The thesis's findings, each with whether it holds on `records` and the figures."""
    return [furniture_finding(records), *noise_findings(records), a_finding(records)]
