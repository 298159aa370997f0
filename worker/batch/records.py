"""A batch record as the tables, figures and pages read it: its summary, its outcome and
reason (a run that raised is failed, "error"), its B errors, and whether its map is good."""

from __future__ import annotations

from typing import Any, TypedDict

from worker.report.summary import RelationErrorsSummary, RelationKind, RunSummary
from worker.status import RecordStatus, RunOutcome, RunReason


class BatchRecord(TypedDict):
    """A finished run's record (`worker.batch.state.record_of`): the fields of its RunSpec,
    how it ended, and where its results are. In memory `summary` is the typed summary;
    record.json holds its persisted form."""

    key: str  # run identity (see worker.batch.experiment.run_key)
    world_path: str
    world: str
    base: str  # the world's name without a furniture suffix
    variant: str  # "furniture" | "no_furniture"
    slam: str
    noise: float  # [m] laser range noise sigma
    seed: int
    params: dict[str, Any]  # RunParams.to_json()
    status: str  # a RecordStatus: done (whatever the outcome) or error (the run raised)
    error: str | None
    summary: RunSummary | None  # None for a run that raised
    run_id: int | None
    job_id: int | None
    report_dir: str | None
    finished_at: str  # ISO 8601, UTC


# Thesis 6.3.4: a map is visually bad above these mean B errors.
GOOD_T = 1.0  # [m]
GOOD_R = 0.03  # [rad]


def summary_of(rec: BatchRecord) -> RunSummary | None:
    """The run's summary; None for a run that raised."""
    return rec["summary"] if rec["status"] == RecordStatus.DONE else None


def outcome_of(rec: BatchRecord) -> tuple[RunOutcome, RunReason | RecordStatus | None]:
    """(outcome, reason): a run that raised counts as failed with reason "error"."""
    s = summary_of(rec)
    if s is None:
        return RunOutcome.FAILED, RecordStatus.ERROR
    return s.outcome, s.reason


def relation_stats(rec: BatchRecord, kind: RelationKind = "B") -> RelationErrorsSummary | None:
    """The run's {translation, rotation, skipped} figures of relation `kind`, if evaluated."""
    s = summary_of(rec)
    return None if s is None else s.relation(kind)


def is_good(rec: BatchRecord) -> bool:
    """Completed, with mean B errors under the thesis's visually-good thresholds."""
    b = relation_stats(rec)
    return (
        outcome_of(rec)[0] == RunOutcome.COMPLETED
        and b is not None
        and b.translation.mean <= GOOD_T
        and b.rotation.mean <= GOOD_R
    )
