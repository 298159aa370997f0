"""`mapqual run`: one floorplan to a full report, stored in the database."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path
from typing import Annotated, Any

import typer

from mapqual.cli import app
from mapqual.cli.world import AllowOutsideOpt
from worker.errors import InputError


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """Deep merge of parameter sections: `over` wins."""
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def build_params(
    params_file: Path | None,
    slam: str | None,
    laser_noise: float | None,
    time_limit: float | None,
):
    """RunParams from SPEC defaults, then the --params file, then the options."""
    from worker.params import load_params_file
    from worker.pipeline import RunParams

    data = load_params_file(params_file) if params_file is not None else {}
    over: dict[str, Any] = {}
    if slam is not None:
        over["algorithm"] = slam
    if laser_noise is not None:
        over["sim"] = {"laser_noise_sigma": laser_noise}
    if time_limit is not None:
        over["explore"] = {"time_limit": time_limit}
    return RunParams.from_json(_merge(data, over))


class _Progress:
    """A rich progress bar on a terminal, a plain line a simulated minute otherwise."""

    def __init__(self, time_limit: float, quiet: bool):
        self.quiet = quiet
        self.tty = sys.stderr.isatty()
        self.next_line = 60.0
        self.bar = None
        if self.tty and not quiet:
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(
                TextColumn("[bold]{task.description}"),
                BarColumn(),
                TextColumn("{task.completed:>6.0f}/{task.total:.0f} s sim"),
                TextColumn("coverage {task.fields[cov]:>4.0%}  x{task.fields[rtf]:.0f} real time"),
                TimeElapsedColumn(),
                transient=True,
            )
            self.task = self.bar.add_task("exploring", total=time_limit, cov=0.0, rtf=0.0)

    def __enter__(self):
        if self.bar is not None:
            self.bar.start()
        return self

    def __exit__(self, *exc):
        if self.bar is not None:
            self.bar.stop()

    def __call__(self, p) -> None:
        if self.bar is not None:
            self.bar.update(self.task, completed=p.t, cov=p.coverage, rtf=p.rtf)
        elif not self.quiet and p.t >= self.next_line:
            self.next_line += 60.0
            print(
                f"t={p.t:7.0f} s  coverage {p.coverage:4.0%}  x{p.rtf:.0f} real time  {p.status}",
                file=sys.stderr,
                flush=True,
            )


@app.command("run")
def run(
    world_path: Annotated[
        Path,
        typer.Argument(
            metavar="WORLD", help="Floorplan: .yaml, .world or an image with --resolution."
        ),
    ],
    seed: Annotated[int, typer.Option(min=0, help="Random seed: same seed, same run.")] = 1,
    slam: Annotated[
        str | None, typer.Option(help="rbpf | odometry | oracle | graph (default rbpf).")
    ] = None,
    laser_noise: Annotated[
        float | None, typer.Option(min=0.0, help="Laser range noise sigma [m].")
    ] = None,
    time_limit: Annotated[
        float | None, typer.Option(min=1.0, help="Simulated-time limit [s].")
    ] = None,
    params_file: Annotated[
        Path | None,
        typer.Option("--params", help="YAML/JSON with sim, slam, explore, eval sections."),
    ] = None,
    resolution: Annotated[float | None, typer.Option(help="m/pixel, for a bare image.")] = None,
    out: Annotated[
        Path | None, typer.Option("-o", "--out", help="Report folder (default runs/<id>/).")
    ] = None,
    as_json: Annotated[
        bool, typer.Option("--json", help="Print the summary as JSON on stdout.")
    ] = False,
    allow_outside: AllowOutsideOpt = False,
) -> None:
    """Simulate, explore with SLAM, evaluate, and store one run of WORLD."""
    from backend.core.config import get_settings
    from backend.db.migrate import upgrade
    from backend.db.session import session_scope
    from backend.execute import run_and_store
    from backend.lifecycle import attempt_dir, new_attempt
    from backend.store import (
        create_job,
        local_user,
        mark_run_failed,
        mark_run_started,
        save_world,
        world_fingerprint,
    )  # fmt: skip
    from worker.pipeline import ALGORITHMS
    from worker.world.loader import load_world

    if slam is not None and slam not in ALGORITHMS:
        raise InputError(f"--slam must be one of {', '.join(ALGORITHMS)}, not {slam!r}")
    params = build_params(params_file, slam, laser_noise, time_limit)
    world = load_world(world_path, resolution, allow_outside=allow_outside)
    settings = get_settings()
    url = settings.database_url
    upgrade(url)
    attempt = new_attempt()
    with session_scope(url) as s:
        owner = local_user(s).id
        row = save_world(
            s,
            owner_id=owner,
            world=world,
            sha256=world_fingerprint(world),
            source_format=world_path.suffix.lstrip(".") or "image",
        )
        job = create_job(
            s,
            owner_id=owner,
            world_id=row.id,
            slam=params.algorithm,
            params=params.to_json(),
            seeds=[seed],
        )
        run_id = job.runs[0].id
        mark_run_started(s, run_id, attempt)
    # the default runs/<id>/ is filled like a worker's: in the attempt's folder, renamed into
    # place with the commit of the result; a folder the user named (-o) is written directly
    shown = out if out is not None else settings.runs_dir / str(run_id)
    out_dir = shown.resolve()
    folder = out_dir if out is not None else attempt_dir(out_dir, attempt)
    try:
        with _Progress(params.explore.time_limit, quiet=as_json) as progress:
            result = run_and_store(
                url, run_id, attempt, (world, params, seed), progress, folder, out_dir,
                rename=out is None,
            )  # fmt: skip
    except BaseException as exc:
        with session_scope(url) as s:
            mark_run_failed(s, run_id, f"{type(exc).__name__}: {exc}", attempt)
        if out is None:
            shutil.rmtree(folder, ignore_errors=True)
        raise
    summary = {"run_id": run_id, "report_dir": str(shown), **result.summary}
    if as_json:
        print(json.dumps(summary))
    else:
        _print_summary(summary)


def _print_summary(s: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    outcome = s["outcome"] + (f" ({s['reason']})" if s["reason"] else "")
    t = s["timings"]
    table = Table(title=f"run {s['run_id']}: {s['world']}, seed {s['seed']}, {s['algorithm']}")
    table.add_column("")
    table.add_column("translation [m]", justify="right")
    table.add_column("rotation [rad]", justify="right")
    table.add_column("relations", justify="right")
    for kind, e in s["relations"].items():
        tr, ro = e["translation"], e["rotation"]
        fmt = lambda v, f: "-" if v is None else format(v, f)  # noqa: E731
        table.add_row(
            f"{kind} mean ± std",
            f"{fmt(tr['mean'], '.3f')} ± {fmt(tr['std'], '.3f')}",
            f"{fmt(ro['mean'], '.4f')} ± {fmt(ro['std'], '.4f')}",
            str(tr["n"]),
        )
    console = Console()
    console.print(table)
    console.print(
        f"outcome [bold]{outcome}[/bold] — {s['stop_detail']}; coverage {s['coverage']:.1%}; "
        f"path {s['path_length_m']:.0f} m; {t['sim_time_s']:.0f} s simulated in "
        f"{t['wall_time_s']:.1f} s (x{t['real_time_factor']:.0f} real time)"
    )
    console.print(f"report: {s['report_dir']}")
