"""`mapqual runs list|show` and `mapqual db upgrade`: read back and maintain the database."""

from __future__ import annotations

import json
from typing import Annotated, Any

import typer

from mapqual.cli import app
from worker.errors import InputError

runs_app = typer.Typer(rich_markup_mode=None, help="Stored runs.", no_args_is_help=True)
db_app = typer.Typer(rich_markup_mode=None, help="The database.", no_args_is_help=True)
app.add_typer(runs_app, name="runs")
app.add_typer(db_app, name="db")


def _fmt(v: float | None, spec: str) -> str:
    return "-" if v is None else format(v, spec)


@runs_app.command("list")
def runs_list(
    limit: Annotated[int, typer.Option(min=1, help="How many runs, newest first.")] = 50,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON array on stdout.")] = False,
) -> None:
    """The most recent runs with their outcome, coverage and B errors."""
    rows = _run_rows(limit)
    if as_json:
        print(json.dumps(rows))
        return
    _print_runs(rows)


def _run_rows(limit: int) -> list[dict[str, Any]]:
    """The newest `limit` runs, one plain mapping each."""
    from dataclasses import asdict

    from backend.services import runs
    from backend.services.database import transaction

    with transaction() as s:  # the embedded database is created and kept current on first use
        found = runs.recent(s, limit)
    return [
        asdict(r) | {"created_at": r.created_at.isoformat() if r.created_at else None}
        for r in found
    ]


def _print_runs(rows: list[dict[str, Any]]) -> None:
    """The runs as a table on the terminal."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title="runs (newest first)")
    for col in (
        "id",
        "world",
        "seed",
        "slam",
        "status",
        "outcome",
        "coverage",
        "B trans [m]",
        "B rot [rad]",
        "sim time [s]",
    ):
        table.add_column(col, justify="right" if col not in ("world", "slam") else "left")
    for r in rows:
        outcome = r["outcome"] or "-"
        if r["reason"]:
            outcome = f"{outcome} ({r['reason']})"
        table.add_row(
            str(r["id"]),
            r["world"] or "-",
            str(r["seed"]),
            r["slam"],
            r["status"],
            outcome,
            _fmt(r["coverage"], ".1%"),
            _fmt(r["b_mean_t"], ".3f"),
            _fmt(r["b_mean_r"], ".4f"),
            _fmt(r["sim_time"], ".0f"),
        )
    Console().print(table)


@runs_app.command("show")
def runs_show(
    run_id: Annotated[int, typer.Argument(help="The run's id.")],
    as_json: Annotated[bool, typer.Option("--json", help="The run's summary as JSON.")] = False,
) -> None:
    """One run: its summary (the report's summary.json) and where its report folder is."""
    from backend.services import runs
    from backend.services.database import transaction
    from backend.services.errors import NotFound

    with transaction() as s:
        try:
            run = runs.any_run(s, run_id)
        except NotFound as exc:
            raise InputError(exc.detail) from None
        doc = {
            "id": run.id,
            "job_id": run.job_id,
            "world_id": run.world_id,
            "seed": run.seed,
            "slam": run.slam,
            "status": run.status,
            "error": run.error,
            "report_dir": run.report_dir,
            "report_files": _report_listing(run.report_dir),
            "summary": run.summary,
        }
    if as_json:
        print(json.dumps(doc))
        return
    from rich.console import Console
    from rich.pretty import Pretty

    Console().print(Pretty(doc))


@db_app.command("upgrade")
def db_upgrade() -> None:
    """Apply the Alembic migrations to DATABASE_URL (creates the SQLite file if needed)."""
    from backend.core.config import get_settings
    from backend.db.migrate import upgrade

    url = get_settings().database_url
    upgrade(url)
    print(f"database at head: {_redact(url)}")


def _redact(url: str) -> str:
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


def _report_listing(location: str | None) -> list[str] | str | None:
    """The files of a run's report, read through the storage layer (local folder or S3), or
    one line saying why they cannot be reached; None for a run with no report."""
    from worker.storage import StorageError, run_files

    if not location:
        return None
    try:
        files = run_files(location)
        files.check()
        return files.names()
    except (StorageError, OSError) as exc:
        return f"unreachable: {exc}"
