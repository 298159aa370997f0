"""A batch's tables: runs.csv, success.csv (thesis Table 6.3), translation.csv and
rotation.csv (Tables 6.4 and 6.5: per environment, B errors averaged over completed runs,
plus CI95, the runs' average 95 % half-width of their mean over the relations)."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from worker.batch.records import BatchRecord, is_good, outcome_of, relation_stats, summary_of
from worker.batch.thesis import THESIS_COLUMNS, side_by_side
from worker.status import RecordStatus, RunOutcome, RunReason

KINDS = (("B", "b"), ("A", "a"), ("SM", "sm"))
STATS = ("mean", "std", "min", "max")
# success.csv's failure columns: stop reasons, then the runs that raised; slam_failed (external
# SLAM programs only) counts among "failed" alone, as success.csv has always been written
REASONS: tuple[RunReason | RecordStatus, ...] = (
    RunReason.COLLISION,
    RunReason.STUCK,
    RunReason.TIME_LIMIT,
    RunReason.SLAM_DIVERGED,
    RecordStatus.ERROR,
)
ERROR_COLUMNS = ("ENVIRONMENT", "MEAN", "STD", "MIN", "MAX", "NUMMEASURES", "CI95")
RUN_LABELS = ("world", "variant", "noise", "slam", "seed")
# runs.csv's map-versus-floorplan columns (issue 17): column <- summary.map_score field
MAP_COLUMNS = (
    ("map_distance_m", "distance_m"),
    ("map_precision", "precision"),
    ("map_recall", "recall"),
    ("map_wall_coverage", "wall_coverage"),
    ("map_free_share", "free_share"),
)


def run_row(rec: BatchRecord) -> dict[str, Any]:
    """One runs.csv row."""
    outcome, reason = outcome_of(rec)
    s = summary_of(rec)
    row: dict[str, Any] = {k: rec[k] for k in RUN_LABELS}
    row.update(outcome=outcome, reason=reason or "", good=is_good(rec))
    row["coverage"] = s and s.coverage
    for kind, prefix in KINDS:
        rel = relation_stats(rec, kind)
        for axis, suffix in (("translation", "t"), ("rotation", "r")):
            stats = getattr(rel, axis) if rel else None
            for stat in STATS:
                row[f"{prefix}_{stat}_{suffix}"] = getattr(stats, stat) if stats else None
            row[f"{prefix}_ci95_{suffix}"] = stats.ci95 if stats else None
        row[f"{prefix}_n"] = rel.translation.n if rel else 0
    ate = s and s.ate
    row["ate_rmse_t"] = ate and ate.translation.rmse
    row["ate_rmse_r"] = ate and ate.rotation.rmse
    timings = s and s.timings
    row["path_length_m"] = s and s.path_length_m
    row["sim_time_s"] = timings and timings.sim_time_s
    row["wall_time_s"] = timings and timings.wall_time_s
    row["real_time_factor"] = timings and timings.real_time_factor
    score = s and s.map_score
    for col, name in MAP_COLUMNS:
        row[col] = getattr(score, name) if score else None
    row.update(run_id=rec.get("run_id"), key=rec["key"], error=rec.get("error") or "")
    return row


def _conditions(records: Sequence[BatchRecord]) -> dict[tuple, list[BatchRecord]]:
    """Records by (world, slam, noise), in order of first appearance."""
    groups: dict[tuple, list[BatchRecord]] = {}
    for rec in records:
        groups.setdefault((rec["world"], rec["slam"], rec["noise"]), []).append(rec)
    return groups


def environment_label(records: Sequence[BatchRecord], world: str, slam: str, noise: float):
    """The world's name, with the SLAM algorithm and noise level when the batch varies them."""
    parts = [world]
    if len({r["slam"] for r in records}) > 1:
        parts.append(slam)
    if len({r["noise"] for r in records}) > 1:
        parts.append(f"noise {noise:g}")
    return " ".join(parts)


def success_rows(records: Sequence[BatchRecord]) -> list[dict[str, Any]]:
    """Per world and condition: runs, completed, good, and failures by reason."""
    rows = []
    for (world, slam, noise), recs in _conditions(records).items():
        outcomes = [outcome_of(r) for r in recs]
        row = {"world": world, "variant": recs[0]["variant"], "noise": noise, "slam": slam}
        row["runs"] = len(recs)
        row["completed"] = sum(o == RunOutcome.COMPLETED for o, _ in outcomes)
        row["good"] = sum(is_good(r) for r in recs)
        # stopped as done with reachable space left unseen: neither done nor a failure
        row["incomplete"] = sum(o == RunOutcome.INCOMPLETE for o, _ in outcomes)
        row["failed"] = row["runs"] - row["completed"] - row["incomplete"]
        for reason in REASONS:
            row[reason] = sum(o == RunOutcome.FAILED and r == reason for o, r in outcomes)
        rows.append(row)
    return rows


def error_rows(records: Sequence[BatchRecord], axis: str) -> list[dict[str, Any]]:
    """Thesis Tables 6.4 (axis "translation") and 6.5 ("rotation"): per environment, each B
    statistic averaged over the completed runs; environments with none are left out. CI95 is
    the average of the runs' 95 % half-widths (over the runs that have one; else None)."""
    rows = []
    for (world, slam, noise), recs in _conditions(records).items():
        stats = [
            getattr(b, axis)
            for r in recs
            if outcome_of(r)[0] == RunOutcome.COMPLETED and (b := relation_stats(r))
        ]
        if not stats:
            continue
        row = {"ENVIRONMENT": environment_label(records, world, slam, noise)}
        for col, stat in zip(ERROR_COLUMNS[1:-1], (*STATS, "n"), strict=True):
            row[col] = float(np.mean([getattr(s, stat) for s in stats]))
        ci = [s.ci95 for s in stats if s.ci95 is not None]
        row["CI95"] = float(np.mean(ci)) if ci else None
        rows.append(row)
    return rows


def map_rows(records: Sequence[BatchRecord]) -> list[dict[str, Any]]:
    """maps.csv: per environment, the map-versus-floorplan scores averaged over the completed
    runs that have one (a score null in a run is left out of its mean)."""
    rows = []
    for (world, slam, noise), recs in _conditions(records).items():
        scores = [
            s.map_score
            for r in recs
            if outcome_of(r)[0] == RunOutcome.COMPLETED
            and (s := summary_of(r)) is not None
            and s.map_score is not None
        ]
        if not scores:
            continue
        row: dict[str, Any] = {"ENVIRONMENT": environment_label(records, world, slam, noise)}
        for col, name in MAP_COLUMNS:
            vals = [v for m in scores if (v := getattr(m, name)) is not None]
            row[col.upper()] = float(np.mean(vals)) if vals else None
        row["RUNS"] = len(scores)
        rows.append(row)
    return rows


def _fmt(v: Any) -> Any:
    if isinstance(v, bool) or v is None:
        return "" if v is None else str(v).lower()
    return repr(v) if isinstance(v, float) else v


def write_csv(path: Path, rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> Path:
    """Rows as CSV with a header line; None is an empty cell, floats round-trip exactly."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(columns)
        for row in rows:
            w.writerow([_fmt(row.get(c)) for c in columns])
    return path


def write_tables(records: Sequence[BatchRecord], out: Path) -> dict[str, Path]:
    """runs.csv, success.csv, translation.csv, rotation.csv, maps.csv and thesis.csv in `out`."""
    runs = [run_row(r) for r in records]
    success = success_rows(records)
    run_cols = list(runs[0]) if runs else list(RUN_LABELS)
    success_cols = ["world", "variant", "noise", "slam", "runs", "completed", "good"]
    success_cols += ["incomplete", "failed"]
    return {
        "runs": write_csv(out / "runs.csv", runs, run_cols),
        "success": write_csv(out / "success.csv", success, [*success_cols, *REASONS]),
        "translation": write_csv(
            out / "translation.csv", error_rows(records, "translation"), ERROR_COLUMNS
        ),
        "rotation": write_csv(out / "rotation.csv", error_rows(records, "rotation"), ERROR_COLUMNS),
        "maps": write_csv(
            out / "maps.csv",
            map_rows(records),
            ["ENVIRONMENT", *(c.upper() for c, _ in MAP_COLUMNS), "RUNS"],
        ),
        "thesis": write_csv(out / "thesis.csv", side_by_side(records), THESIS_COLUMNS),
    }
