"""`mapqual batch`: worlds x seeds x SLAM algorithms x laser noise on a headless server, in a
local process pool or through Celery; resumable; tables, figures and report.html in OUT."""

from __future__ import annotations

import fnmatch
import shlex
import signal
import sys
import time
from dataclasses import replace
from functools import partial
from pathlib import Path
from typing import Annotated, Any

import typer

from mapqual.cli import app
from mapqual.cli.world import AllowOutsideOpt
from worker.errors import InputError
from worker.status import RecordStatus


def _cores() -> int:
    from worker.slam.threads import cores

    return cores()


class BatchProgress:
    """A rich progress bar with ETA on a terminal; one plain line per finished run otherwise."""

    def __init__(self, total: int, done: int):
        self.total, self.done, self.done0 = total, done, done
        self.t0 = time.monotonic()
        self.running: dict[str, str] = {}
        self.bar = None
        if sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self.bar = Progress(
                TextColumn("[bold]batch"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                TextColumn("{task.fields[running]}"),
                console=Console(stderr=True),
            )
            self.task = self.bar.add_task("batch", total=total, completed=done, running="")

    def __enter__(self) -> BatchProgress:
        if self.bar is not None:
            self.bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()

    def _eta(self) -> str:
        n = self.done - self.done0
        if n == 0:
            return "?"
        left = (time.monotonic() - self.t0) / n * (self.total - self.done)
        return time.strftime("%H:%M:%S", time.gmtime(left))

    def __call__(self, ev) -> None:
        spec = ev.spec
        if ev.kind == "start":
            self.running[spec.key] = f"{spec.world} s{spec.seed}"
        elif ev.kind == "progress":
            self.running[spec.key] = f"{spec.world} s{spec.seed} {ev.t:.0f}s"
        else:
            self.running.pop(spec.key, None)
            self.done += 1
            if self.bar is None:
                print(f"[{self.done:>4}/{self.total}] {spec.label}: {_line(ev.record)}"
                      f"  (ETA {self._eta()})", file=sys.stderr, flush=True)  # fmt: skip
        if self.bar is not None:
            running = ", ".join(list(self.running.values())[:4])
            self.bar.update(self.task, completed=self.done, running=running)


def _line(rec: dict[str, Any]) -> str:
    from worker.batch.tables import outcome_of, relation_stats

    outcome, reason = outcome_of(rec)
    text = outcome + (f" ({reason})" if reason else "")
    if rec["status"] != RecordStatus.DONE:
        return f"{text}: {rec['error']}"
    b = relation_stats(rec)
    if b is not None:
        text += f", B {b.translation.mean:.3f} m {b.rotation.mean:.4f} rad"
    t = rec["summary"].timings
    return text + f", {t.sim_time_s:.0f} s simulated in {t.wall_time_s:.0f} s"


def _overrides(worlds, runs, seeds, slam, laser_noise) -> dict[str, Any]:
    if runs is not None and seeds is not None:
        raise InputError("give --runs or --seeds, not both")
    return {
        "worlds": [str(w) for w in worlds] or None,
        "runs": runs,
        "seeds": seeds,
        "slam": slam,
        "laser_noise": laser_noise,
    }


def _terminate(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt  # SIGTERM cleans up like Ctrl-C: workers stopped, runs requeued


WorldsArg = Annotated[
    list[Path] | None,
    typer.Argument(metavar="WORLDS", help="Floorplan files (.yaml, .world) or folders."),
]
RunsOpt = Annotated[int | None, typer.Option(min=1, help="Seeds 1..N per condition.")]
SeedsOpt = Annotated[str | None, typer.Option(help="Seeds: A-B or a list, e.g. 1-10.")]
SlamOpt = Annotated[str | None, typer.Option(help="Algorithms, e.g. rbpf,odometry.")]
NoiseOpt = Annotated[str | None, typer.Option(help="Laser noise sigmas [m], e.g. 0,0.1,0.3.")]
ParamsOpt = Annotated[
    Path | None,
    typer.Option("--params", help="YAML/JSON with sim, slam, explore, eval sections."),
]
TimeLimitOpt = Annotated[
    float | None, typer.Option(min=1.0, help="Simulated-time limit of each run [s].")
]
ExperimentOpt = Annotated[
    str | None, typer.Option(help="Experiment YAML file, or 'thesis' (bundled).")
]
OnlyOpt = Annotated[
    str | None, typer.Option(help="Keep only worlds whose file name matches this glob.")
]
WorkersOpt = Annotated[
    int | None, typer.Option(min=1, help="Local worker processes (default: cores).")
]
CeleryOpt = Annotated[
    bool, typer.Option("--celery", help="Run on Celery workers (REDIS_URL) instead.")
]
RetryOpt = Annotated[
    bool, typer.Option("--retry-failed", help="Redo runs that stopped on an internal error.")
]
SimLogOpt = Annotated[
    bool, typer.Option("--sim-log", help="Keep each run's full CARMEN log (large).")
]
DryRunOpt = Annotated[
    bool, typer.Option("--dry-run", help="List the runs and how many are left; run none.")
]
OutOpt = Annotated[Path, typer.Option("-o", "--out", help="Output folder.")]
TrainOpt = Annotated[
    Path | None,
    typer.Option(
        "--train-model",
        help="Then train the map-quality model on this batch's runs and write it here (JSON).",
    ),
]


@app.command("batch")
def batch(
    worlds: WorldsArg = None,
    runs: RunsOpt = None,
    seeds: SeedsOpt = None,
    slam: SlamOpt = None,
    laser_noise: NoiseOpt = None,
    params_file: ParamsOpt = None,
    time_limit: TimeLimitOpt = None,
    experiment: ExperimentOpt = None,
    only: OnlyOpt = None,
    workers: WorkersOpt = None,
    celery: CeleryOpt = False,
    retry_failed: RetryOpt = False,
    sim_log: SimLogOpt = False,
    dry_run: DryRunOpt = False,
    out: OutOpt = Path("batch"),
    allow_outside: AllowOutsideOpt = False,
    train_model: TrainOpt = None,
) -> None:
    """Run an experiment (WORLDS x seeds x --slam x --laser-noise) and write its tables,
    figures and report.html to OUT. Re-running the same command resumes it.

    An experiment file (YAML) holds the keys worlds, runs or seeds, slam, laser_noise and
    params (sim, slam, explore, eval sections), and optionally a list of groups with the
    same keys: the experiment is the union of their products. Options override the file's
    values; --only narrows its worlds. --train-model FILE then fits the model of `mapqual
    predict` on this batch's runs (all of them so far: a resumed batch trains on more) and
    writes it to FILE, for `mapqual predict --model FILE`.
    """
    from worker.batch.state import BatchDir

    if worlds and experiment:
        raise InputError("give WORLDS or --experiment, not both (--only GLOB narrows one)")
    if workers is not None and celery:
        raise InputError("--workers is for the local pool; Celery workers are started apart")
    choices = (worlds or [], runs, seeds, slam, laser_noise)
    specs, loaded = _specs(experiment, choices, params_file, time_limit, only, allow_outside)
    bdir = BatchDir(out)
    if dry_run:
        todo = _todo(bdir, specs, retry_failed)
        for s in specs:
            print(f"{s.key}  {'todo' if s in todo else RecordStatus.DONE}  {s.label}")
        return
    command = "mapqual " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    with bdir.lock():  # one batch process per folder
        todo = _todo(bdir, specs, retry_failed)
        bdir.describe(command=command, runs=len(specs), mode="celery" if celery else "local")
        _execute(specs, todo, loaded, bdir, workers or _cores(), celery, retry_failed,
                 sim_log, allow_outside=allow_outside)  # fmt: skip
    if train_model is not None:
        from mapqual.cli.predict import train_to

        dirs = sorted({Path(s.world_path).parent for s in specs})  # where its worlds lie
        train_to([out], train_model, dirs, command, allow_outside)


def _todo(bdir, specs, retry_failed: bool) -> list[Any]:
    """The runs still to do (no record yet, or --retry-failed and not done), and one line."""
    records = bdir.load_records(s.key for s in specs)
    redo = {k for k, r in records.items() if retry_failed and r["status"] != RecordStatus.DONE}
    todo = [s for s in specs if s.key not in records or s.key in redo]
    print(f"{len(specs)} runs, {len(specs) - len(todo)} finished, {len(todo)} to do -> "
          f"{bdir.root}", file=sys.stderr)  # fmt: skip
    return todo


def _specs(
    experiment: str | None,
    choices: tuple[Any, ...],
    params_file: Path | None,
    time_limit: float | None,
    only: str | None,
    allow_outside: bool,
) -> tuple[list[Any], dict[str, Any]]:
    """The experiment's runs (from its file, then the options: `choices` = worlds, runs,
    seeds, slam, laser_noise) and its worlds, loaded."""
    from worker.batch.experiment import build_groups, expand, load_experiment, load_params, merge
    from worker.world.loader import load_world

    raw, base_dir = load_experiment(experiment) if experiment else ({}, None)
    base_params = load_params(params_file)
    if time_limit is not None:
        base_params = merge(base_params, {"explore": {"time_limit": time_limit}})
    groups = build_groups(raw, base_dir, _overrides(*choices), base_params)
    if only is not None:
        groups = _only(groups, only)
    return expand(groups, partial(load_world, allow_outside=allow_outside))


def _only(groups, pattern: str):
    """The groups narrowed to the worlds whose file name matches `pattern`."""
    kept = []
    for g in groups:
        worlds = tuple(p for p in g.worlds if fnmatch.fnmatch(Path(p).stem, pattern))
        if worlds:
            kept.append(replace(g, worlds=worlds))
    if not kept:
        raise InputError(f"--only {pattern!r} matches none of the experiment's worlds")
    return kept


def _execute(
    specs, todo, loaded, bdir, workers, celery, retry_failed, sim_log, *, allow_outside=False
) -> None:
    from backend.core.config import get_settings
    from backend.db.migrate import upgrade
    from backend.services.batch import DbBatch
    from worker.batch.local import run_local
    from worker.batch.remote import run_celery
    from worker.batch.results import write_results

    settings = get_settings()
    upgrade(settings.database_url)
    db = DbBatch(settings, bdir.batch_id(), specs, loaded)
    previous = signal.signal(signal.SIGTERM, _terminate)
    try:
        with BatchProgress(len(specs), len(specs) - len(todo)) as progress:
            if celery:
                run_celery(todo, bdir, db, progress, retry_failed=retry_failed)
            else:
                # runs a killed invocation left `running` are this pool's to redo: queued
                db.interrupted(todo)
                run_local(todo, bdir, workers, db, progress, sim_log=sim_log,
                          allow_outside=allow_outside, fn=db.pool_run())  # fmt: skip
    finally:
        signal.signal(signal.SIGTERM, previous)
        records = bdir.load_records(s.key for s in specs)
        ordered = [records[s.key] for s in specs if s.key in records]
        if ordered:
            write_results(ordered, bdir, len(specs))
    _print_tables(bdir.root)


def _print_tables(out: Path) -> None:
    import csv

    from rich.console import Console
    from rich.table import Table

    console = Console()
    if not console.is_terminal:  # a log file: wide enough for every column
        console = Console(width=160)
    for name, title in (("success.csv", "success"), ("translation.csv", "B translation [m]"),
                        ("rotation.csv", "B rotation [rad]")):  # fmt: skip
        with open(out / name, newline="") as fh:
            rows = list(csv.reader(fh))
        table = Table(title=title)
        for col in rows[0]:
            table.add_column(col, justify="left" if col in ("world", "ENVIRONMENT") else "right")
        for row in rows[1:]:
            table.add_row(*[_short(v) for v in row])
        console.print(table)
    console.print(f"report: {out / 'report.html'}")


def _short(v: str) -> str:
    try:
        f = float(v)
    except ValueError:
        return v
    return v if v.isdigit() else f"{f:.4g}"
