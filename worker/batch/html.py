"""report.html: a batch's tables and figures on one self-contained page (images embedded)."""

from __future__ import annotations

import base64
import html
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from worker.batch.state import now_iso
from worker.batch.tables import (
    ERROR_COLUMNS,
    error_rows,
    is_good,
    outcome_of,
    success_rows,
    summary_of,
)

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
STYLE = """
body{font-family:system-ui,sans-serif;margin:2em auto;max-width:1200px;color:#222}
table{border-collapse:collapse;margin:0.5em 0 1.5em;font-size:0.85em}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}
img{max-width:100%;border:1px solid #ddd}figure{margin:1em 0 2em}
figcaption{color:#555;font-size:0.9em}.bad{color:#b00}.good{color:#070}
"""


def _e(v: Any) -> str:
    return html.escape(str(v))


def _num(v: Any, digits: int = 4) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return _e(v)


# columns shown with fewer digits than the errors
DIGITS = {"noise": None, "NUMMEASURES": 1}


def _table(rows: Sequence[dict[str, Any]], columns: Sequence[str], left: int = 1) -> str:
    head = "".join(
        f'<th class="{"l" if i < left else ""}">{_e(c)}</th>' for i, c in enumerate(columns)
    )
    body = []
    for row in rows:
        cells = "".join(
            f'<td class="{"l" if i < left else ""}">{_cell(row.get(c), c)}</td>'
            for i, c in enumerate(columns)
        )
        body.append(f"<tr>{cells}</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _cell(v: Any, column: str) -> str:
    if column not in DIGITS or not isinstance(v, float):
        return _num(v)
    digits = DIGITS[column]
    return f"{v:g}" if digits is None else f"{v:.{digits}f}"


def _runs_table(records: Sequence[dict[str, Any]], out: Path) -> str:
    rows = []
    for r in records:
        outcome, reason = outcome_of(r)
        s = summary_of(r)
        b = s.relations.get("B") if s else None
        cls = "good" if is_good(r) else "bad"
        link = _e(r["world"])
        map_png = Path(r["report_dir"] or "") / "map.png"
        if r["report_dir"] and map_png.is_file():
            link = f'<a href="{_e(os.path.relpath(map_png, out))}">{link}</a>'
        what = outcome + (f" ({reason})" if reason else "")
        if r.get("error"):
            what += f": {r['error']}"
        rows.append(
            f'<tr><td class="l">{link}</td><td>{r["seed"]}</td><td class="l">{_e(r["slam"])}</td>'
            f'<td>{r["noise"]:g}</td><td class="l {cls}">{_e(what)}</td>'
            f"<td>{_num(s and s.coverage, 3)}</td><td>{_num(b and b.translation.mean)}</td>"
            f"<td>{_num(b and b.rotation.mean)}</td><td>{b.translation.n if b else 0}</td>"
            f"<td>{_num(s and s.timings.sim_time_s, 0)}</td></tr>"
        )
    head = (
        '<tr><th class="l">world</th><th>seed</th><th class="l">slam</th><th>noise [m]</th>'
        '<th class="l">outcome</th><th>coverage</th><th>B mean t [m]</th><th>B mean r [rad]</th>'
        "<th>B relations</th><th>sim time [s]</th></tr>"
    )
    return f"<table>{head}{''.join(rows)}</table>"


def _figure(name: str, path: Path | None) -> str:
    if path is None or not path.is_file():
        return f"<p><i>{_e(name)}: not drawn ({_e(MISSING[name])}).</i></p>"
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    return (
        f'<figure><img alt="{_e(name)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{_e(CAPTIONS[name])} ({_e(name)})</figcaption></figure>"
    )


def write_html(
    records: Sequence[dict[str, Any]],
    figures: dict[str, Path | None],
    out: Path,
    info: dict[str, Any],
    expected: int,
) -> Path:
    """report.html in `out`, readable offline: every image is embedded in the page."""
    done = sum(outcome_of(r)[0] == "completed" for r in records)
    good = sum(is_good(r) for r in records)
    errors = sum(r["status"] != "done" for r in records)
    head = (
        f"<h1>mapqual batch {_e(info.get('batch_id', ''))}</h1>"
        f"<p>{_e(info.get('command', ''))}</p>"
        f"<p>{len(records)} of {expected} runs finished: {done} completed, {good} visually good "
        f"(B mean under 1 m and 0.03 rad), {errors} internal errors. Written {now_iso()}.</p>"
    )
    success_cols = ["world", "variant", "noise", "slam", "runs", "completed", "good", "failed"]
    success_cols += ["collision", "stuck", "time_limit", "slam_diverged", "error"]
    parts = [
        head,
        "<h2>Success (thesis Table 6.3)</h2>",
        _table(success_rows(records), success_cols),
        "<h2>Translational B error [m] (Table 6.4; averages over completed runs)</h2>",
        _table(error_rows(records, "translation"), ERROR_COLUMNS),
        "<h2>Rotational B error [rad] (Table 6.5)</h2>",
        _table(error_rows(records, "rotation"), ERROR_COLUMNS),
        "<h2>Figures</h2>",
        *(_figure(name, path) for name, path in figures.items()),
        "<h2>Runs</h2><details><summary>every run (links open its map)</summary>",
        _runs_table(records, out),
        "</details>",
    ]
    page = (
        '<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
        f"<title>mapqual batch</title><style>{STYLE}</style></head><body>"
        + "\n".join(parts)
        + "</body></html>\n"
    )
    path = out / "report.html"
    path.write_text(page, encoding="utf-8")
    return path
