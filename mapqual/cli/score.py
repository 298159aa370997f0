"""`mapqual score`: an external estimate of a run's motion, scored on the run's own relations."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from mapqual.cli import app
from worker.errors import InputError


class EstFmt(StrEnum):
    auto = "auto"
    tum = "tum"
    carmen = "carmen"
    bag = "bag"


def _reachable(location: str) -> bool:
    from worker.storage import StorageError, run_files

    try:
        run_files(location).check()
    except (StorageError, OSError) as exc:
        if location.startswith("s3://"):
            raise InputError(f"the run's report cannot be reached ({exc})") from None
        return False
    return True


def _resolve_run(run: str) -> tuple[Path | str, int | None]:
    """(report folder, database run id or None) of RUN: a stored run's id, or a run folder
    (then the database run whose report folder it is, if there is one)."""
    from backend.services import runs
    from backend.services.database import migrated_url, transaction
    from backend.services.errors import NotFound

    if run.isdigit():
        with transaction() as s:
            try:
                row = runs.any_run(s, int(run))
            except NotFound:
                raise InputError(f"no run {run} in the database") from None
            if not row.report_dir or not _reachable(row.report_dir):
                raise InputError(f"run {run} has no report folder (yet)")
            return row.report_dir, row.id
    folder = Path(run)
    if not folder.is_dir():
        raise InputError("no such run folder (or run id)", path=folder)
    want = folder.resolve()
    try:
        url = migrated_url()
    except Exception:  # no database to record it in: the folder alone is scored
        return folder, None
    with transaction(url) as s:
        rows = runs.report_dirs(s)
    found = [rid for rid, d in rows if not d.startswith("s3://") and Path(d).resolve() == want]
    return folder, (found[-1] if found else None)


def _score_stored(location: str, traj, name: str, source: str, **kw) -> tuple[object, str]:
    """Score on a run kept in object storage: its parts fetched, the estimate's folder
    written back beside them. (the score, that folder's location)"""
    import tempfile

    from worker.export.score import ESTIMATES_DIR, RUN_PARTS, score_estimate
    from worker.storage import run_files

    files = run_files(location)
    with tempfile.TemporaryDirectory(prefix="mapqual-score-") as tmp:
        run_dir = files.fetch(RUN_PARTS, Path(tmp) / "run")
        score = score_estimate(run_dir, traj, name, source, out_dir=Path(tmp) / "est", **kw)
        target = files.sub(f"{ESTIMATES_DIR}/{name}")
        target.put_tree("", Path(tmp) / "est")
    return score, target.location


def _store(run_id: int, score, est, location: str) -> None:
    from backend.services import runs
    from backend.services.database import transaction

    with transaction() as s:
        runs.store_estimate(s, run_id, summary=score.summary, t=est.t, poses=est.poses,
                            report_dir=location)  # fmt: skip


@app.command("score")
def score_cmd(
    run: Annotated[str, typer.Argument(help="Run folder, or the id of a stored run.")],
    est: Annotated[
        Path, typer.Option(help="Estimate: TUM, CARMEN, or a bag (.bag / rosbag2 dir).")
    ],
    name: Annotated[str, typer.Option(help="The algorithm's name (its report subfolder).")] = (
        "external"
    ),
    fmt: Annotated[EstFmt, typer.Option("--format", help="Format of --est.")] = EstFmt.auto,
    topic: Annotated[str | None, typer.Option(help="Bag: the pose topic (default: found).")] = None,
    max_gap: Annotated[
        float | None, typer.Option(help="Interpolate only within this many s (the run's).")
    ] = None,
    allow_frame_offset: Annotated[
        bool, typer.Option(help="Score an estimate whose frame is offset from the run's.")
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Score an estimate with the run's B, A and SM relations; write <run>/estimates/NAME/ and
    store it as another algorithm of the run."""
    from mapqual.cli.evaluate import _stats_table
    from worker.export.checks import CheckParams
    from worker.export.estimate import read_estimate
    from worker.export.score import check_name, score_estimate

    check_name(name)
    if max_gap is not None and not max_gap > 0:
        raise InputError("--max-gap must be > 0")
    folder, run_id = _resolve_run(run)
    traj = read_estimate(est, fmt.value, topic)
    checks = CheckParams(frame=not allow_frame_offset)
    if isinstance(folder, str) and folder.startswith("s3://"):
        score, where = _score_stored(folder, traj, name, est.name, max_gap=max_gap, checks=checks)
        shown = where
    else:
        score = score_estimate(folder, traj, name, est.name, max_gap=max_gap, checks=checks)
        where, shown = str(score.folder.resolve()), str(score.folder)
    if run_id is not None:
        _store(run_id, score, traj, where)
    doc = dict(score.summary, report_dir=shown, run_id=run_id)
    if as_json:
        print(json.dumps(doc))
        return
    for kind, summary in score.summary["relations"].items():
        _stats_table(
            f"{kind} relations: {name} on run {run}", summary, ["mean", "std", "min", "max", "n"]
        )
    stored = f", stored as algorithm {name!r} of run {run_id}" if run_id is not None else ""
    print(f"wrote {shown}{stored}")
