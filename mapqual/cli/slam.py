"""`mapqual slam`: run a SLAM algorithm over a CARMEN log; write the map and the trajectory."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from mapqual.cli import app
from mapqual.cli.progress import ScanBar
from worker.slam import registry

# the registered algorithms that can replay a recorded log (the oracle needs ground truth)
Algorithm = StrEnum("Algorithm", {name: name for name in registry.names(offline=True)})


def _opt(help_text: str):
    return typer.Option(help=help_text, show_default=False)


LogArg = Annotated[Path, typer.Argument(help="CARMEN log: ROBOTLASER1, or FLASER + ODOM lines.")]
OutOpt = Annotated[Path, typer.Option("--out", "-o", help="Output folder.")]
AlgorithmOpt = Annotated[Algorithm, typer.Option(help="SLAM algorithm.")]
SeedOpt = Annotated[int, typer.Option(help="Random seed: same seed, same output.")]
ParamsOpt = Annotated[
    Path | None,
    typer.Option("--params", help="YAML/JSON of SLAM parameters (or a `slam:` section)."),
]
TemporalOpt = Annotated[float | None, _opt("temporalUpdate [s], <0 off [default -1].")]
StrOpt = Annotated[float | None, typer.Option("--str", help="Motion noise str [default 0.1].")]
ThreadsOpt = Annotated[int | None, _opt("Scan-matching threads; same output [default 1].")]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")]


@app.command("slam")
def slam(
    log: LogArg,
    out: OutOpt,
    algorithm: AlgorithmOpt = Algorithm.rbpf,
    seed: SeedOpt = 0,
    params_file: ParamsOpt = None,
    particles: Annotated[int | None, _opt("Particles [default 40].")] = None,
    linear_update: Annotated[float | None, _opt("linearUpdate [m] [default 1.0].")] = None,
    angular_update: Annotated[float | None, _opt("angularUpdate [rad] [default 0.25].")] = None,
    temporal_update: TemporalOpt = None,
    delta: Annotated[float | None, _opt("Map resolution [m] [default 0.05].")] = None,
    max_urange: Annotated[float | None, _opt("maxUrange [m] [default 30].")] = None,
    max_range: Annotated[float | None, _opt("maxRange [m] [default laser max - 0.01].")] = None,
    lskip: Annotated[int | None, _opt("Beams skipped when matching [default 0].")] = None,
    srr: Annotated[float | None, _opt("Motion noise srr [default 0.1].")] = None,
    srt: Annotated[float | None, _opt("Motion noise srt [default 0.2].")] = None,
    str_: StrOpt = None,
    stt: Annotated[float | None, _opt("Motion noise stt [default 0.2].")] = None,
    threads: ThreadsOpt = None,
    as_json: JsonOpt = False,
) -> None:
    """Run SLAM over LOG with the odometry pose of each laser line; write DIR/map.pgm,
    DIR/map.yaml, DIR/map.png, DIR/trajectory.log (FLASER lines, the estimate at every laser
    timestamp), DIR/trajectory.tum and DIR/slam.json. For rbpf and graph the trajectory is
    the final one (the best particle's path; the optimised graph) and DIR/online.tum holds
    the estimate each scan had when it was processed."""
    options = {
        "particles": particles, "linear_update": linear_update,
        "angular_update": angular_update, "temporal_update": temporal_update, "delta": delta,
        "max_urange": max_urange, "max_range": max_range, "lskip": lskip, "srr": srr,
        "srt": srt, "str_": str_, "stt": stt, "threads": threads,
    }  # fmt: skip
    params = _slam_params(params_file, options)
    summary, result = _run(log, out, algorithm.value, seed, params, quiet=as_json)
    (out / "slam.json").write_text(json.dumps(summary, indent=2) + "\n")
    if as_json:
        print(json.dumps(summary))
    else:
        print(
            f"{algorithm.value}: {summary['scans']} scans, {result.updates} updates, "
            f"{result.wall_s:.1f} s ({result.real_time_factor:.0f}x real time) -> {out}"
        )


def _slam_params(params_file: Path | None, options: dict[str, Any]) -> Any:
    """SlamParams from the defaults, then the --params file, then the options given."""
    from worker.param_io import from_dict, load_params_file
    from worker.slam.params import SlamParams

    given: dict[str, Any] = {}
    if params_file is not None:
        data = load_params_file(params_file)
        given.update(data.get("slam", data) if isinstance(data.get("slam"), dict) else data)
    given.update({k: v for k, v in options.items() if v is not None})
    return from_dict(SlamParams, given, "slam")


def _run(
    log: Path, out: Path, algorithm: str, seed: int, params: Any, quiet: bool
) -> tuple[dict[str, Any], Any]:
    """Run SLAM over the log, write the map and trajectory files into `out`: (the summary,
    the SLAM result)."""
    import numpy as np

    from worker.evaluate.trajio import write_carmen, write_tum
    from worker.param_io import to_dict
    from worker.sim.carmen import read_laser_log
    from worker.slam.run import run_slam

    data = read_laser_log(log)
    out.mkdir(parents=True, exist_ok=True)
    with ScanBar(quiet=quiet) as progress:
        result = run_slam(
            data.t, data.pose_odom, data.ranges, data.laser, algorithm, params,
            np.random.default_rng(seed), on_progress=progress,
        )  # fmt: skip
    result.grid.save_map_server(out / "map")
    result.grid.save_png(out / "map.png")
    write_carmen(out / "trajectory.log", result.trajectory)
    write_tum(out / "trajectory.tum", result.trajectory)
    if result.online is not result.trajectory:
        write_tum(out / "online.tum", result.online)
    summary = {
        "log": str(log),
        "algorithm": algorithm,
        "seed": seed,
        "scans": int(len(data.t)),
        "updates": result.updates,
        "log_duration_s": round(result.log_duration_s, 3),
        "wall_s": round(result.wall_s, 3),
        "real_time_factor": round(result.real_time_factor, 1),
        "map_cells": list(result.grid.shape),
        "params": to_dict(result.params),
    }
    return summary, result
