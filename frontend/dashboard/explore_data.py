"""The results explorer's data: every done run as a flat row (world, algorithm, seed, the
parameters it changed from the defaults, outcome, coverage, scores), filtered, and grouped by
world x algorithm x setting with mean, spread and 95 % intervals.

Outcome and scores are separate facts: a run that hit its time limit, or gave up frontiers,
still has its relations scored, and counts with those scores unless the user leaves its kind
of outcome out.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np
from scipy import stats
from sqlalchemy import Text, cast, select

from backend.db.models import Run, World
from backend.services.access import Principal
from worker.status import RunOutcome, RunStatus

KINDS = ("completed", "incomplete", "time limit", "failed")  # outcome kinds, as filtered
DEFAULT_KINDS = ("completed", "incomplete", "time limit")  # scored runs that ran their course
GROUP_KEYS = ("world", "slam", "setting")
SCORES = ("b_t", "b_r", "a_t", "sm_t")  # B / A / SM mean errors of a run [m, rad, m, m]
SCORE_NAMES = {"b_t": "B trans. [m]", "b_r": "B rot. [rad]", "a_t": "A trans. [m]",
               "sm_t": "SM trans. [m]"}  # fmt: skip
CONFIDENCE = 0.95
DEFAULT_SETTING = "defaults"


def outcome_kind(outcome: str | None, reason: str | None) -> str:
    """completed, incomplete, time limit (a failure by the clock alone) or failed."""
    if outcome == RunOutcome.COMPLETED:
        return "completed"
    if outcome == RunOutcome.INCOMPLETE:
        return "incomplete"
    return "time limit" if reason == "time_limit" else "failed"


@lru_cache(maxsize=64)
def _defaults(algorithm: str) -> dict[str, Any]:
    from worker.run_params import RunParams

    try:
        return _flatten(RunParams(algorithm=algorithm).to_json())  # type: ignore[arg-type]
    except Exception:  # an algorithm this code no longer knows: compare with rbpf's
        return _flatten(RunParams().to_json())


def _flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    if not isinstance(d, dict):
        return {prefix: d}
    out: dict[str, Any] = {}
    for k, v in d.items():
        out.update(_flatten(v, f"{prefix}.{k}" if prefix else str(k)))
    return out


def changed_params(params: dict[str, Any] | None) -> dict[str, Any]:
    """The run's parameters that differ from its algorithm's defaults, as dotted keys."""
    flat = _flatten(params or {})
    algorithm = str(flat.pop("algorithm", "rbpf"))
    base = _defaults(algorithm)
    return {k: v for k, v in sorted(flat.items()) if k in base and base[k] != v}


def setting_label(changed: dict[str, Any]) -> str:
    """A setting's name: its changed parameters (the explore's time limit first), or defaults."""
    if not changed:
        return DEFAULT_SETTING
    keys = sorted(changed, key=lambda k: (k != "explore.time_limit", k))
    return ", ".join(f"{k.split('.', 1)[-1]}={_short(changed[k])}" for k in keys)


def _short(v: Any) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


@dataclass
class RunRow:
    """One done run as the explorer shows it."""

    id: int
    job_id: int
    world: str
    slam: str
    seed: int
    outcome: str
    reason: str | None
    kind: str
    coverage: float | None
    b_t: float | None
    b_r: float | None
    a_t: float | None
    sm_t: float | None
    changed: dict[str, Any] = field(default_factory=dict)
    setting: str = DEFAULT_SETTING

    def key(self, by: Sequence[str]) -> tuple[str, ...]:
        return tuple(str(getattr(self, k)) for k in by)


def _mean_of(kind: str):
    """The SQL of a run's mean translational error of relation `kind` (from its metrics JSON,
    read by the database: parsing every run's JSON in Python was most of the page's time)."""
    return Run.metrics["relations"][kind]["translation"]["mean"].as_float()


@lru_cache(maxsize=4096)
def _setting_of(params_text: str | None) -> tuple[dict[str, Any], str]:
    """(changed parameters, setting label) of a run's stored parameters as JSON text: runs of
    one job share their text, so each is parsed and compared with the defaults once."""
    changed = changed_params(json.loads(params_text) if params_text else None)
    return changed, setting_label(changed)


# run id -> (A, SM) mean errors: a done run's scores never change, and reading them out of
# the metrics JSON is most of the database's work for the page (json, not jsonb, is parsed per
# row); bounded, so a server's memory does not grow with the database
_AUX: dict[int, tuple[float | None, float | None]] = {}
AUX_MAX = 200_000


def _aux_scores(session, ids: list[int]) -> dict[int, tuple[float | None, float | None]]:
    missing = [i for i in ids if i not in _AUX]
    for k in range(0, len(missing), 5000):
        chunk = missing[k : k + 5000]
        stmt = select(Run.id, _mean_of("A"), _mean_of("SM")).where(Run.id.in_(chunk))
        if len(_AUX) + len(chunk) > AUX_MAX:
            _AUX.clear()
        for rid, a, sm in session.execute(stmt):
            _AUX[rid] = (a, sm)
    return {i: _AUX.get(i, (None, None)) for i in ids}


def load_runs(session, user: Principal, job_id: int | None = None) -> list[RunRow]:
    """Every done run `user` may see (an administrator: all), oldest first; of one job only
    with `job_id`."""
    stmt = (
        select(Run.id, Run.job_id, World.name, Run.slam, Run.seed, Run.outcome, Run.reason,
               Run.coverage, Run.b_mean_t, Run.b_mean_r, cast(Run.params, Text))
        .join(World, World.id == Run.world_id)
        .where(Run.status == RunStatus.DONE)
        .order_by(Run.id)
    )  # fmt: skip
    if not user.is_admin:
        stmt = stmt.where(Run.owner_id == user.id)
    if job_id is not None:
        stmt = stmt.where(Run.job_id == job_id)
    found = session.execute(stmt).all()
    aux = _aux_scores(session, [r[0] for r in found])
    rows = []
    for rid, job, world, slam, seed, outcome, reason, cov, bt, br, params in found:
        changed, setting = _setting_of(params)
        rows.append(RunRow(
            rid, job, world, slam, seed, str(outcome), reason, outcome_kind(outcome, reason), cov,
            bt, br, *aux[rid], changed, setting,
        ))  # fmt: skip
    return rows


@dataclass
class Filters:
    """What the user keeps: worlds, algorithms, settings (empty: all) and outcome kinds."""

    worlds: tuple[str, ...] = ()
    slams: tuple[str, ...] = ()
    settings: tuple[str, ...] = ()
    kinds: tuple[str, ...] = DEFAULT_KINDS
    group_by: tuple[str, ...] = GROUP_KEYS
    jobs: tuple[int, ...] = ()

    def keep(self, r: RunRow) -> bool:
        return (
            (not self.jobs or r.job_id in self.jobs)
            and (not self.worlds or r.world in self.worlds)
            and (not self.slams or r.slam in self.slams)
            and (not self.settings or r.setting in self.settings)
            and r.kind in self.kinds
        )

    def apply(self, rows: Iterable[RunRow]) -> list[RunRow]:
        return [r for r in rows if self.keep(r)]


@dataclass
class Stat:
    """Mean, sample std (ddof 1), t-based 95 % interval of the mean, and n."""

    n: int
    mean: float | None
    std: float | None
    low: float | None
    high: float | None


def describe(values: Iterable[float | None]) -> Stat:
    v = np.array([x for x in values if x is not None and math.isfinite(x)], dtype=float)
    if v.size == 0:
        return Stat(0, None, None, None, None)
    mean = float(v.mean())
    if v.size < 2:
        return Stat(1, mean, None, None, None)
    std = float(v.std(ddof=1))
    half = float(stats.t.ppf(0.5 + CONFIDENCE / 2, v.size - 1)) * std / math.sqrt(v.size)
    return Stat(int(v.size), mean, std, mean - half, mean + half)


def wilson(k: int, n: int, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval of a proportion k/n (exact at the ends, unlike the normal one)."""
    if n == 0:
        return (0.0, 1.0)
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass
class Group:
    """The runs of one world x algorithm x setting (or whichever keys the user groups by)."""

    key: tuple[str, ...]
    by: tuple[str, ...]
    runs: list[RunRow]
    scores: dict[str, Stat]
    coverage: Stat
    completed: int
    success: tuple[float, float]  # Wilson 95 % interval of the success rate
    kinds: dict[str, int]

    @property
    def label(self) -> str:
        return " · ".join(self.key) if self.key else "all runs"

    @property
    def ident(self) -> str:
        return "|".join(self.key)

    @property
    def success_rate(self) -> float:
        return self.completed / len(self.runs) if self.runs else 0.0


def group(rows: Sequence[RunRow], by: Sequence[str]) -> list[Group]:
    """The groups of `rows` by `by` (world, slam, setting), sorted by key."""
    buckets: dict[tuple[str, ...], list[RunRow]] = {}
    for r in rows:
        buckets.setdefault(r.key(by), []).append(r)
    out = []
    for key in sorted(buckets):
        runs = buckets[key]
        done = sum(r.kind == "completed" for r in runs)
        kinds: dict[str, int] = {}
        for r in runs:
            kinds[r.kind] = kinds.get(r.kind, 0) + 1
        out.append(Group(
            key, tuple(by), runs, {s: describe(getattr(r, s) for r in runs) for s in SCORES},
            describe(r.coverage for r in runs), done, wilson(done, len(runs)), kinds,
        ))  # fmt: skip
    return out


def param_columns(rows: Iterable[RunRow]) -> list[str]:
    """Every parameter some shown run changed from its defaults: the runs table's columns."""
    return sorted({k for r in rows for k in r.changed})


def job_result(slam: str, runs: Iterable[Any]) -> dict[str, Any]:
    """What a job's finished runs came to: outcomes by kind (in KINDS order), how many have B
    scores, and the algorithm's mean B translational error over them."""
    kinds: dict[str, int] = {}
    scored = []
    for r in runs:
        if r.status != RunStatus.DONE:
            continue
        k = outcome_kind(r.outcome, r.reason)
        kinds[k] = kinds.get(k, 0) + 1
        if r.b_mean_t is not None:
            scored.append(float(r.b_mean_t))
    ordered = [(k, kinds[k]) for k in KINDS if k in kinds]
    b = describe(scored)
    return {"kinds": ordered, "slam": slam, "scored": b.n, "b_mean": b.mean,
            "none_completed": bool(kinds) and "completed" not in kinds}  # fmt: skip


def settings_used(params: dict[str, Any] | None) -> dict[str, Any]:
    """The settings a run used, for its job's page: the time limit (and whether it is the
    default), the laser and odometry noise, and every parameter changed from the defaults."""
    flat = _flatten(params or {})
    base = _defaults(str(flat.get("algorithm", "rbpf")))
    key = "explore.time_limit"
    noise = {k: v for k, v in flat.items() if k.startswith("sim.") and "noise" in k}
    return {"time_limit": flat.get(key), "time_limit_default": flat.get(key) == base.get(key),
            "noise": noise, "changed": changed_params(params)}  # fmt: skip
