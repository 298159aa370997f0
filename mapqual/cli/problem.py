"""`mapqual problem`: a SLAM problem from a corrected CARMEN log (drifting odometry, true poses)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from mapqual.cli import app


@app.command("problem")
def problem(
    log: Annotated[
        Path, typer.Argument(help="Corrected CARMEN log: its scan poses are the ground truth.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")],
    seed: Annotated[int, typer.Option(help="Random seed of the drift: same seed, same log.")] = 0,
    scale_std: Annotated[
        float, typer.Option(help="Std of the per-run scale error of each axis (x, y, theta).")
    ] = 0.03,
    step_noise: Annotated[
        float, typer.Option(help="Per-step noise std, relative to each step component.")
    ] = 0.05,
    first: Annotated[int, typer.Option(help="First scan taken.")] = 0,
    scans: Annotated[int | None, typer.Option(help="Scans taken (default: all).")] = None,
) -> None:
    """Write DIR/problem.log (CARMEN ODOM + ROBOTLASER1 + TRUEPOS: the log's real scans with
    odometry made to drift, seeded) and DIR/gt.tum (the corrected poses at the same times),
    and DIR/problem.json. Then: `mapqual slam DIR/problem.log -o RUN` and `mapqual evaluate
    --gt DIR/gt.tum --est RUN/trajectory.tum`."""
    from worker.errors import InputError
    from worker.evaluate.trajio import write_tum
    from worker.sim.carmen import read_laser_log
    from worker.sim.drift import DriftParams, drifting_problem, log_slice, write_problem_log

    params = DriftParams(scale_std=scale_std, step_noise=step_noise)
    data = read_laser_log(log)
    n = data.t.shape[0]
    stop = n if scans is None else first + scans
    if first < 0 or stop > n or stop - first < 2:
        raise InputError(f"--first {first} --scans {scans}: the log has {n} scans", path=log)
    data = log_slice(data, first, stop)
    drifted, gt = drifting_problem(data, seed, params)
    out.mkdir(parents=True, exist_ok=True)
    comment = f"mapqual problem {log.name} --seed {seed}: odometry made to drift, TRUEPOS = log"
    write_problem_log(out / "problem.log", drifted, comment)
    write_tum(out / "gt.tum", gt)
    summary = _summary(log, seed, first, params, data, drifted)
    (out / "problem.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"{summary['scans']} scans, scale {summary['scale']} -> {out}")


def _summary(
    log: Path, seed: int, first: int, params: Any, data: Any, drifted: Any
) -> dict[str, Any]:
    """problem.json: where the problem comes from, the drift drawn, and the laser."""
    import numpy as np

    from worker.sim.drift import drift_odometry

    # the scale errors the seed drew (drift_odometry draws them first, from the same stream)
    _, scale = drift_odometry(data.pose_odom, np.random.default_rng(seed), params)
    return {
        "log": str(log),
        "seed": seed,
        "scans": int(drifted.t.shape[0]),
        "first": first,
        "scale_std": params.scale_std,
        "step_noise": params.step_noise,
        "scale": [round(float(s), 6) for s in scale],
        "laser": {
            "n_beams": drifted.laser.n_beams,
            "angle_min": drifted.laser.angle_min,
            "angle_increment": drifted.laser.angle_increment,
            "range_max": drifted.laser.range_max,
        },
        "notes": list(data.notes),
    }
