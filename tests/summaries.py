"""Run summaries for tests: a real summary.json (examples/office_a) with the figures a test sets."""

from __future__ import annotations

import copy
import json
from functools import cache
from pathlib import Path
from typing import Any

from worker.report.summary import RunSummary

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "office_a" / "summary.json"


@cache
def _example() -> dict[str, Any]:
    return json.loads(EXAMPLE.read_text())


def stats(mean: float | None, std: float | None = 0.0, n: int = 1, **rest: Any) -> dict:
    """One error axis: `mean`, `std`, `n`; min and max default to the mean."""
    lo, hi = rest.get("min", mean), rest.get("max", mean)
    ms = rest.get("mean_squared")
    return {"mean": mean, "std": std, "min": lo, "max": hi, "n": n, "mean_squared": ms}


def relation(t: dict, r: dict | None = None, skipped: int = 0) -> dict:
    """One relation kind's errors (rotation defaults to the translation's figures)."""
    return {"translation": t, "rotation": t if r is None else r, "skipped": skipped}


def _merge(base: dict[str, Any], changes: dict[str, Any]) -> dict[str, Any]:
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict) and key != "relations":
            _merge(base[key], value)
        else:
            base[key] = value
    return base


def summary_doc(**changes: Any) -> dict[str, Any]:
    """office_a's summary.json as data with `changes` merged in (nested mappings merge, except
    `relations`, which replaces the example's kinds)."""
    return _merge(copy.deepcopy(_example()), changes)


def make_summary(**changes: Any) -> RunSummary:
    """The typed summary of `summary_doc(**changes)`."""
    return RunSummary.model_validate(summary_doc(**changes))
