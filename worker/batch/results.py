"""Everything a batch writes to OUT from its records: tables, figures and report.html."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from worker.batch.html import write_html
from worker.batch.plots import write_plots
from worker.batch.records import BatchRecord
from worker.batch.state import BatchDir
from worker.batch.tables import write_tables


def write_results(
    records: Sequence[BatchRecord], bdir: BatchDir, expected: int
) -> dict[str, Path | None]:
    """runs.csv, success.csv, translation.csv, rotation.csv, maps.csv, the figures and
    report.html of the finished runs (`expected`: how many runs the batch has in all)."""
    out = bdir.root
    files: dict[str, Path | None] = dict(write_tables(records, out))
    figures = write_plots(records, out)
    files.update(figures)
    files["report"] = write_html(records, figures, out, bdir.info(), expected)
    return files
