"""Store a real pipeline result as a finished run, the way a worker does (for API tests)."""

from __future__ import annotations

from pathlib import Path

from backend.db.session import session_scope
from backend.store import mark_run_started, store_run_result


def store_finished_run(url: str, run_id: int, result, report_dir: Path | None) -> None:
    """Mark `run_id` started and store `result` (a `RunResult`) with its report folder."""
    ex = result.exploration
    report = None if report_dir is None else str(report_dir)
    with session_scope(url) as s:
        mark_run_started(s, run_id)
        store_run_result(
            s, run_id, summary=result.summary, t=ex.t, pose_gt=ex.pose_gt, pose_est=ex.pose_est,
            map_ros=ex.final_map.to_ros(), map_resolution=ex.final_map.resolution,
            map_origin=ex.final_map.origin, report_dir=report,
        )  # fmt: skip
