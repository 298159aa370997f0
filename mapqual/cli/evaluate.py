"""`mapqual relations`, `mapqual evaluate`, `mapqual ate`: thin shells over worker.evaluate."""

from __future__ import annotations

import dataclasses
import json
import sys
import warnings
from enum import StrEnum
from pathlib import Path
from typing import Annotated, Any

import typer

from mapqual.cli import app
from worker.errors import InputError


class Kind(StrEnum):
    A = "A"
    B = "B"
    SM = "SM"
    L = "L"
    M = "M"
    S = "S"


class Fmt(StrEnum):
    auto = "auto"
    carmen = "carmen"
    tum = "tum"


class Message(StrEnum):
    auto = "auto"
    FLASER = "FLASER"
    ROBOTLASER1 = "ROBOTLASER1"
    TRUEPOS = "TRUEPOS"
    ODOM = "ODOM"


FmtOpt = Annotated[Fmt, typer.Option("--format", help="Trajectory file format.")]
MaxGapOpt = Annotated[
    float,
    typer.Option(help="Interpolate only between poses within this many seconds."),
]

# Which --kind each kind-specific option applies to (given for another kind: an error).
_KIND_OPTIONS: dict[str, set[str]] = {
    "--dt": {"A", "S", "SM"},
    "--distance": {"M", "SM"},
    "--radius": {"L"},
    "--away": {"L"},
    "--z": {"B"},
    "--margin": {"B"},
    "--pilot": {"B"},
    "--max-relations": {"B", "SM"},
    "--min-relations": {"B"},
    "--est": {"B"},
}


def _params(kind: str, given: dict[str, Any]) -> Any:
    """The kind's frozen parameters with the options the user gave (None: default)."""
    from worker.evaluate import relations as r

    for opt, value in given.items():
        if value is not None and kind not in _KIND_OPTIONS[opt]:
            kinds = ", ".join(sorted(_KIND_OPTIONS[opt]))
            raise InputError(f"{opt} applies to --kind {kinds}, not {kind}")
    names = {
        "A": (r.AParams, {"dt": "--dt"}),
        "S": (r.SParams, {"dt": "--dt"}),
        "M": (r.MParams, {"distance": "--distance"}),
        "SM": (
            r.SMParams,
            {"dt": "--dt", "min_distance": "--distance", "max_relations": "--max-relations"},
        ),
        "L": (r.LParams, {"radius": "--radius", "away": "--away"}),
        "B": (
            r.BParams,
            {
                "z": "--z",
                "margin": "--margin",
                "pilot": "--pilot",
                "max_relations": "--max-relations",
                "min_relations": "--min-relations",
            },
        ),
    }
    cls, fields = names[kind]
    return cls(**{f: given[o] for f, o in fields.items() if given.get(o) is not None})


@app.command("relations")
def relations_cmd(
    gt: Annotated[Path, typer.Argument(help="Ground-truth trajectory (CARMEN log or TUM).")],
    kind: Annotated[Kind, typer.Option(help="Relation generator.")],
    output: Annotated[Path, typer.Option("-o", "--output", help="Relations file to write.")],
    est: Annotated[Path | None, typer.Option(help="Estimate (needed by --kind B).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed (B).")] = 0,
    fmt: FmtOpt = Fmt.auto,
    message: Annotated[Message, typer.Option(help="CARMEN message of the ground truth.")] = (
        Message.auto
    ),
    est_message: Annotated[Message, typer.Option(help="CARMEN message of the estimate.")] = (
        Message.auto
    ),
    dt: Annotated[float | None, typer.Option(help="A/S/SM: step, s (0.5/10/2).")] = None,
    distance: Annotated[float | None, typer.Option(help="M: step, SM: gap, m (2/5).")] = None,
    radius: Annotated[float | None, typer.Option(help="L: return radius, m (0.2).")] = None,
    away: Annotated[float | None, typer.Option(help="L: distance to leave first, m (0.5).")] = None,
    z: Annotated[float | None, typer.Option(help="B: critical value z (1.96).")] = None,
    margin: Annotated[float | None, typer.Option(help="B: margin of error E, m (0.05).")] = None,
    pilot: Annotated[int | None, typer.Option(help="B: pilot relations for s (500).")] = None,
    max_relations: Annotated[int | None, typer.Option(help="B: cap (1e6); SM: limit.")] = None,
    min_relations: Annotated[int | None, typer.Option(help="B: floor on N (500).")] = None,
    max_gap: MaxGapOpt = 0.1,
) -> None:
    """Generate ground-truth relations of one kind and write them (t1 t2 x y z roll pitch yaw)."""
    import numpy as np

    from worker.evaluate import relations as r
    from worker.evaluate.trajio import read_trajectory, write_relations

    k = kind.value
    if k == "B" and est is None:
        raise InputError("--kind B needs --est: the estimate's pilot errors set how many relations")
    given = {
        "--dt": dt,
        "--distance": distance,
        "--radius": radius,
        "--away": away,
        "--z": z,
        "--margin": margin,
        "--pilot": pilot,
        "--max-relations": max_relations,
        "--min-relations": min_relations,
        "--est": est,
    }
    params = _params(k, given)
    if k == "B":
        params = dataclasses.replace(params, max_gap=max_gap)
    traj_gt = read_trajectory(gt, fmt.value, message.value)
    traj_est = None if est is None else read_trajectory(est, fmt.value, est_message.value)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", r.RelationsCapWarning)
        rng = np.random.default_rng(seed)
        rel = r.generate_relations(k, traj_gt, params, est=traj_est, rng=rng)
    for w in caught:
        print(f"mapqual: warning: {w.message}", file=sys.stderr)
    write_relations(output, rel)
    print(f"wrote {len(rel)} {k} relations to {output}")


def _stats_table(title: str, summary: dict[str, Any], fields: list[str]) -> None:
    """One row per statistic, one column per component: narrow enough for any terminal."""
    from rich.console import Console
    from rich.table import Table

    def cell(value: float | int | None, field: str) -> str:
        if value is None:
            return "-"
        return str(value) if field == "n" else f"{value:.6g}"

    table = Table(title=title)
    table.add_column("")
    table.add_column("translation (m)", justify="right")
    table.add_column("rotation (rad)", justify="right")
    for f in fields:
        name = {"mean_squared": "mean of squares", "ci95": "mean's 95 % CI ±"}.get(f, f)
        table.add_row(name, cell(summary["translation"][f], f), cell(summary["rotation"][f], f))
    console = Console()
    console.print(table)
    console.print(f"skipped: {summary['skipped']}")


@app.command("evaluate")
def evaluate_cmd(
    relations: Annotated[Path, typer.Option(help="Relations file (t1 t2 x y z roll pitch yaw).")],
    est: Annotated[Path, typer.Option(help="Estimated trajectory (CARMEN log or TUM).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    output: Annotated[
        Path | None,
        typer.Option("-o", "--output", help="Directory for T.errors, R.errors, summary.json."),
    ] = None,
    fmt: FmtOpt = Fmt.auto,
    message: Annotated[Message, typer.Option(help="CARMEN message of the estimate.")] = (
        Message.auto
    ),
    max_gap: MaxGapOpt = 0.1,
) -> None:
    """Score an estimate on relations: translational and rotational error statistics."""
    from worker.evaluate.metric import evaluate_relations
    from worker.evaluate.textio import write_text
    from worker.evaluate.trajio import read_relations, read_trajectory, write_errors

    rel = read_relations(relations)
    traj_est = read_trajectory(est, fmt.value, message.value)
    errors = evaluate_relations(rel, traj_est, max_gap=max_gap)
    summary = errors.summary()
    if output is not None:
        try:
            output.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot create directory: {exc.strerror}", path=output) from None
        ok = errors.evaluated
        t1, t2 = errors.t1[ok], errors.t2[ok]
        write_errors(output / "T.errors", t1, t2, errors.translation[ok])
        write_errors(output / "R.errors", t1, t2, errors.rotation[ok])
        write_text(output / "summary.json", json.dumps(summary, indent=2) + "\n")
    if as_json:
        print(json.dumps(summary))
    else:
        fields = ["mean", "std", "min", "max", "n", "mean_squared", "ci95"]
        _stats_table(f"relations metric: {relations.name} on {est.name}", summary, fields)


@app.command("ate")
def ate_cmd(
    gt: Annotated[Path, typer.Option(help="Ground-truth trajectory (CARMEN log or TUM).")],
    est: Annotated[Path, typer.Option(help="Estimated trajectory (CARMEN log or TUM).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    fmt: FmtOpt = Fmt.auto,
    gt_message: Annotated[Message, typer.Option(help="CARMEN message of the ground truth.")] = (
        Message.auto
    ),
    est_message: Annotated[Message, typer.Option(help="CARMEN message of the estimate.")] = (
        Message.auto
    ),
    max_gap: MaxGapOpt = 0.1,
) -> None:
    """Absolute trajectory error after a least-squares SE(2) alignment (no scale)."""
    from worker.evaluate.ate import absolute_trajectory_error
    from worker.evaluate.trajio import read_trajectory

    traj_gt = read_trajectory(gt, fmt.value, gt_message.value)
    traj_est = read_trajectory(est, fmt.value, est_message.value)
    summary = absolute_trajectory_error(traj_gt, traj_est, max_gap=max_gap).summary()
    if as_json:
        print(json.dumps(summary))
    else:
        a = summary["alignment"]
        fields = ["rmse", "mean", "std", "min", "max", "n"]
        _stats_table(f"ATE: {est.name} against {gt.name}", summary, fields)
        print(f"alignment T_gt_est: x={a['x']:.6g} m, y={a['y']:.6g} m, theta={a['theta']:.6g} rad")
