"""`mapqual run`: one floorplan to a full report, stored in the database."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from mapqual.cli import app
from mapqual.cli.progress import RunBar
from mapqual.cli.world import AllowOutsideOpt
from worker.errors import InputError
from worker.slam import registry

if TYPE_CHECKING:
    from worker.report.summary import RunSummary
    from worker.run_params import RunParams
    from worker.world.world import World as WorldModel


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
    realtime: float | None = None,
):
    """RunParams from SPEC defaults, then the --params file, then the options."""
    from worker.param_io import load_params_file
    from worker.run_params import RunParams

    data = load_params_file(params_file) if params_file is not None else {}
    over: dict[str, Any] = {}
    if slam is not None:
        over["algorithm"] = slam
    if laser_noise is not None:
        over["sim"] = {"laser_noise_sigma": laser_noise}
    if time_limit is not None:
        over["explore"] = {"time_limit": time_limit}
    if realtime is not None:
        over["realtime"] = {"speed": realtime}
    return RunParams.from_json(_merge(data, over))


WorldArg = Annotated[
    Path,
    typer.Argument(metavar="WORLD", help="Floorplan: .yaml, .world or an image with --resolution."),
]
SeedOpt = Annotated[int, typer.Option(min=0, help="Random seed: same seed, same run.")]
SlamOpt = Annotated[
    str | None, typer.Option(help=f"{' | '.join(registry.names())} (default rbpf).")
]
NoiseOpt = Annotated[float | None, typer.Option(min=0.0, help="Laser range noise sigma [m].")]
TimeLimitOpt = Annotated[float | None, typer.Option(min=1.0, help="Simulated-time limit [s].")]
ParamsOpt = Annotated[
    Path | None,
    typer.Option("--params", help="YAML/JSON with sim, slam, explore, eval sections."),
]
ResolutionOpt = Annotated[float | None, typer.Option(help="m/pixel, for a bare image.")]
OutOpt = Annotated[
    Path | None, typer.Option("-o", "--out", help="Report folder (default runs/<id>/).")
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the summary as JSON on stdout.")]
RealtimeOpt = Annotated[
    float | None,
    typer.Option(
        "--realtime",
        metavar="SPEED",
        help="Emulate real-time SLAM: each update takes simulated time (cost model / SPEED, "
        "the robot computer's speed against the calibration machine); scans meanwhile dropped.",
    ),
]


@app.command("run")
def run(
    world_path: WorldArg,
    seed: SeedOpt = 1,
    slam: SlamOpt = None,
    laser_noise: NoiseOpt = None,
    time_limit: TimeLimitOpt = None,
    params_file: ParamsOpt = None,
    resolution: ResolutionOpt = None,
    out: OutOpt = None,
    as_json: JsonOpt = False,
    allow_outside: AllowOutsideOpt = False,
    realtime: RealtimeOpt = None,
) -> None:
    """Simulate, explore with SLAM, evaluate, and store one run of WORLD. The run's scan
    matcher uses every core this process may run on (MAPQUAL_SLAM_THREADS=1 keeps it to one;
    the result is the same)."""
    from worker.kernel_cache import warm_kernels
    from worker.slam.threads import claim_default
    from worker.world.loader import load_world

    claim_default(1)

    if slam is not None and slam not in registry.names():
        raise InputError(f"--slam must be one of {', '.join(registry.names())}, not {slam!r}")
    params = build_params(params_file, slam, laser_noise, time_limit, realtime)
    world = load_world(world_path, resolution, allow_outside=allow_outside)
    warm_kernels(params.algorithm, announce=_announce_compiling)
    run_id, shown, summary = _execute(world, world_path.suffix, params, seed, out, as_json)
    if as_json:
        print(json.dumps({"run_id": run_id, "report_dir": str(shown), **summary.to_dict()}))
    else:
        _print_summary(summary, run_id, str(shown))


def _announce_compiling() -> None:
    if not sys.stderr.isatty():  # as the progress bar: a pipe or a log gets the summary only
        return
    print("mapqual: compiling the kernels, once for this version (about a minute)",
          file=sys.stderr, flush=True)  # fmt: skip


def _execute(
    world: WorldModel, suffix: str, params: RunParams, seed: int, out: Path | None, quiet: bool
) -> tuple[int, Path | str, RunSummary]:
    """Store the world and a job of one run, and execute it with the run service: the default
    runs/<id>/ is filled like a worker's (in the attempt's folder, renamed into place with the
    commit of the result); a folder the user named (-o) is written directly. (run id, report
    folder as shown (an s3:// location with S3 storage), summary); a failed run is one line
    on stderr and exit code 1."""
    from backend.core.config import get_settings
    from backend.db.migrate import upgrade
    from backend.services.execute import Placement, execute_run

    settings = get_settings()
    upgrade(settings.database_url)
    run_id = _store_job(settings.database_url, world, suffix, params, seed)
    place = Placement(report_dir=out, own_folder=out is not None, fail_on_interrupt=True)
    with RunBar(params.explore.time_limit, quiet=quiet) as progress:
        outcome = execute_run(run_id, settings, place=place, on_progress=progress, world=world)
    if outcome.summary is None:
        print(f"mapqual: error: {outcome.message}", file=sys.stderr)
        raise typer.Exit(1)
    if out is not None:
        return run_id, out, outcome.summary
    if outcome.report_dir and outcome.report_dir.startswith("s3://"):  # kept in object storage
        return run_id, outcome.report_dir, outcome.summary
    return run_id, settings.runs_dir / str(run_id), outcome.summary


def _store_job(url: str, world: WorldModel, suffix: str, params: RunParams, seed: int) -> int:
    """The world (found again by its content) and a new job of one run for it: the run's id."""
    from backend.services import runs
    from backend.services.database import transaction

    with transaction(url) as s:
        return runs.create_local_run(s, world, suffix.lstrip(".") or "image", params, seed)


def _print_summary(s: RunSummary, run_id: int, report_dir: str) -> None:
    from rich.console import Console
    from rich.table import Table

    outcome = s.outcome + (f" ({s.reason})" if s.reason else "")
    t = s.timings
    table = Table(title=f"run {run_id}: {s.world}, seed {s.seed}, {s.algorithm}")
    table.add_column("")
    table.add_column("translation [m]", justify="right")
    table.add_column("rotation [rad]", justify="right")
    table.add_column("relations", justify="right")
    for kind, e in s.relations.items():
        tr, ro = e.translation, e.rotation
        fmt = lambda v, f: "-" if v is None else format(v, f)  # noqa: E731
        table.add_row(
            f"{kind} mean ± std",
            f"{fmt(tr.mean, '.3f')} ± {fmt(tr.std, '.3f')}",
            f"{fmt(ro.mean, '.4f')} ± {fmt(ro.std, '.4f')}",
            str(tr.n),
        )
    console = Console()
    console.print(table)
    rtf = t.real_time_factor  # under 10 (an emulated SLAM is often under 1): with tenths
    rtf_text = f"{rtf:.1f}" if rtf < 10 else f"{rtf:.0f}"
    console.print(
        f"outcome [bold]{outcome}[/bold] — {s.stop_detail}; coverage {s.coverage:.1%}; "
        f"path {s.path_length_m:.0f} m; {t.sim_time_s:.0f} s simulated in "
        f"{t.wall_time_s:.1f} s (x{rtf_text} real time)"
    )
    rt = s.realtime
    if rt is not None:
        console.print(
            f"real-time SLAM (speed {rt.speed:g}): {rt.updates} updates, {rt.scans_dropped} of "
            f"{rt.scans} scans dropped, latency mean {rt.latency_mean_s:.3f} s, max "
            f"{rt.latency_max_s:.3f} s"
        )
    console.print(f"report: {report_dir}")
