"""report.html: a batch's tables and figures on one self-contained page (images embedded),
rendered from the Jinja2 template `templates/report.html` (autoescaped)."""

from __future__ import annotations

import base64
import os
from collections.abc import Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

from jinja2 import Environment, PackageLoader, StrictUndefined, Template

from worker.batch.paired import batch_paired_rows
from worker.batch.records import BatchRecord, is_good, outcome_of, summary_of
from worker.batch.state import now_iso
from worker.batch.tables import ERROR_COLUMNS, REASONS, error_rows, success_rows
from worker.batch.thesis import findings, side_by_side
from worker.batch.validity import validity
from worker.status import RecordStatus, RunOutcome

CAPTIONS = {
    "errors_by_world.png": (
        "Errors per environment (thesis Figs. 6.8, 6.9): mean B error with its standard "
        "deviation, and the max error on the right axis; averages over completed runs."
    ),
    "furniture.png": "The same environments without and with furniture (thesis Fig. 6.3).",
    "noise.png": "Success and error against laser range noise (thesis Figs. 6.4 to 6.6).",
    "a_vs_b.png": (
        "Mean A against mean B error of each run: A relations (consecutive poses) stay small "
        "in bad maps too, B relations separate good from bad runs; that is why B is the score."
    ),
}
MISSING = {
    "errors_by_world.png": "no completed run with B relations yet",
    "furniture.png": "no environment in the batch in both variants",
    "noise.png": "no world run at more than one noise level",
    "a_vs_b.png": "no run with both A and B relations",
}


def _num(v: Any, digits: int = 4) -> str:
    """A table figure: floats to `digits` decimals, None as a dash."""
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


# columns shown with fewer digits than the errors
DIGITS = {"noise": None, "NUMMEASURES": 1}


def _cell(v: Any, column: str) -> str:
    if column not in DIGITS or not isinstance(v, float):
        return _num(v)
    digits = DIGITS[column]
    return f"{v:g}" if digits is None else f"{v:.{digits}f}"


@lru_cache(maxsize=1)
def _template() -> Template:
    env = Environment(
        loader=PackageLoader("worker.batch", "templates"),
        autoescape=True,
        trim_blocks=True,
        lstrip_blocks=True,
        undefined=StrictUndefined,
        keep_trailing_newline=True,
    )
    env.filters.update(num=_num, cell=_cell, g=lambda v: f"{v:g}")
    return env.get_template("report.html")


def _run_row(r: BatchRecord, out: Path) -> dict[str, Any]:
    """One line of the runs table: labels, outcome, coverage, B means, B count, sim time."""
    outcome, reason = outcome_of(r)
    s = summary_of(r)
    b = s.relations.get("B") if s else None
    link = _map_link(r, out)
    what = outcome + (f" ({reason})" if reason else "")
    if r.get("error"):
        what += f": {r['error']}"
    return {
        "world": r["world"], "link": link, "seed": r["seed"], "slam": r["slam"],
        "noise": r["noise"], "cls": "good" if is_good(r) else "bad", "what": what,
        "coverage": s and s.coverage, "b_mean_t": b and b.translation.mean,
        "b_mean_r": b and b.rotation.mean, "b_n": b.translation.n if b else 0,
        "b_ci_t": b and b.translation.ci95, "b_ci_r": b and b.rotation.ci95,
        "sim_time_s": s and s.timings.sim_time_s,
    }  # fmt: skip


def _map_link(r: BatchRecord, out: Path) -> str | None:
    """The run's map.png relative to the batch's folder: its report's file on this disk, or
    (object storage) a copy fetched into OUT/maps/; None when it cannot be had."""
    from worker.storage import StorageError, run_files

    if not r.get("report_dir"):
        return None
    try:
        files = run_files(r["report_dir"])
        path = files.local_path("map.png")
        if path is None:
            name = f"{r.get('key') or r.get('run_id')}.png".replace("/", "_")
            path = files.storage.get_file(files.key("map.png"), out / "maps" / name)
    except (StorageError, OSError):
        return None
    return os.path.relpath(path, out) if path.is_file() else None


def _figure(name: str, path: Path | None) -> dict[str, Any]:
    data = None
    if path is not None and path.is_file():
        data = base64.b64encode(path.read_bytes()).decode("ascii")
    return {"name": name, "data": data, "caption": CAPTIONS[name], "missing": MISSING[name]}


def _validity(records: Sequence[BatchRecord], out: Path) -> dict[str, Any] | None:
    """The validity section with its scatter plot embedded (None: too few scored runs)."""
    v = validity(records, out)
    if v is not None:
        plot = v.pop("plot")
        v["data"] = base64.b64encode(plot.read_bytes()).decode("ascii") if plot else None
    return v


def write_html(
    records: Sequence[BatchRecord],
    figures: dict[str, Path | None],
    out: Path,
    info: dict[str, Any],
    expected: int,
) -> Path:
    """report.html in `out`, readable offline: every image is embedded in the page."""
    success_cols = ["world", "variant", "noise", "slam", "runs", "completed", "good"]
    success_cols += ["incomplete", "failed", *REASONS]
    page = _template().render(
        info=info,
        finished=len(records),
        expected=expected,
        completed=sum(outcome_of(r)[0] == RunOutcome.COMPLETED for r in records),
        good=sum(is_good(r) for r in records),
        errors=sum(r["status"] != RecordStatus.DONE for r in records),
        written=now_iso(),
        success=success_rows(records),
        success_columns=success_cols,
        translation=error_rows(records, "translation"),
        rotation=error_rows(records, "rotation"),
        error_columns=ERROR_COLUMNS,
        figures=[_figure(name, path) for name, path in figures.items()],
        runs=[_run_row(r, out) for r in records],
        thesis=side_by_side(records),
        findings=findings(records),
        paired=batch_paired_rows(records),
        validity=_validity(records, out),
    )
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path
