"""`mapqual predict WORLD` and `mapqual predict train BATCH_OUT... -o model.json`: map quality
predicted from a floorplan alone, and the model that does it trained on batch tables."""

from __future__ import annotations

import json
import math
import shlex
import sys
from pathlib import Path
from typing import Annotated

import typer

from mapqual.cli import app
from mapqual.cli.world import AllowOutsideOpt
from worker.errors import InputError

ArgsArg = Annotated[
    list[str],
    typer.Argument(
        metavar="WORLD | train BATCH_OUT...",
        help="A floorplan (image with --resolution, map_server YAML, Stage .world), or `train` "
        "and batch output folders (their runs.csv).",
    ),
]


@app.command("predict")
def predict_cmd(
    args: ArgsArg,
    slam: Annotated[str, typer.Option(help="SLAM algorithm the prediction is for.")] = "rbpf",
    model: Annotated[
        Path | None, typer.Option(help="Model file (default: the bundled one).")
    ] = None,
    resolution: Annotated[
        float | None, typer.Option(help="Metres per pixel (needed for a bare image).")
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print one JSON object.")] = False,
    out: Annotated[
        Path | None, typer.Option("-o", "--out", help="train: where to write the model.")
    ] = None,
    worlds: Annotated[
        list[Path] | None,
        typer.Option(help="train: folders holding the batch's worlds (default: ./worlds)."),
    ] = None,
    allow_outside: AllowOutsideOpt = False,
) -> None:
    """Predict the mean B errors (80 % interval) and success probability of a SLAM run on a
    floorplan, with the features that drove them; or train the model (`predict train`)."""
    if args and args[0] == "train":
        _train(args[1:], out, worlds, allow_outside)
        return
    if len(args) != 1:
        raise InputError("give one WORLD (or `train BATCH_OUT... -o model.json`)")
    if out is not None or worlds:
        raise InputError("-o and --worlds are for `mapqual predict train`")
    _predict(Path(args[0]), slam, model, resolution, as_json, allow_outside)


def _train(batches: list[str], out: Path | None, worlds, allow_outside: bool) -> None:
    from worker.world.catalogue import default_worlds_dir

    if not batches:
        raise InputError("give the batch output folders to train on")
    if out is None:
        raise InputError("give -o model.json")
    command = "mapqual " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    train_to([Path(b) for b in batches], out, worlds or [default_worlds_dir()], command,
             allow_outside)  # fmt: skip


def train_to(
    batches: list[Path], out: Path, world_dirs: list[Path], command: str, allow_outside: bool
) -> None:
    """Train the model on `batches` (their runs.csv, the worlds found in `world_dirs`), write
    it to `out` (JSON) and print its cross-validated accuracy (`predict train`, `batch
    --train-model`)."""
    from worker.predict.fit import train_model

    data = train_model(batches, world_dirs, command=command, allow_outside=allow_outside)
    out.write_text(json.dumps(data, indent=1) + "\n", encoding="utf-8")
    print(f"model: {out}  ({data['training']['description']})")
    for slam, part in data["slam"].items():
        cv = part["cv"].get("b_mean_t")
        if cv:
            t, m, a = cv["trees"], cv["mean"], cv["free_area"]
            print(
                f"{slam} leave-one-building-out, mean B translation: Spearman "
                f"{t['spearman_worlds']:.2f}; MAE {t['mae']:.3f} m (training mean "
                f"{m['mae']:.3f} m, free area alone {a['mae']:.3f} m)"
            )


def _predict(path: Path, slam, model_path, resolution, as_json, allow_outside) -> None:
    from worker.predict.model import load_model, predict
    from worker.world.features import FEATURE_DOCS, features_of
    from worker.world.loader import load_world

    model = load_model(model_path)  # a bad model file fails before the world is analysed
    world = load_world(path, resolution, allow_outside=allow_outside)
    p = predict(model, features_of(world, allow_outside=allow_outside), slam)
    if as_json:
        print(json.dumps({"world": world.name, **p.as_dict()}))
        return
    t, r = p.b_mean_t, p.b_mean_r
    print(f"{'world':>22}: {world.name}  ({slam})")
    print(f"{'mean B translation':>22}: {t.median:.3f} m  (80 % interval {t.low:.3f} to "
          f"{t.high:.3f} m; linear model {t.linear:.3f} m)")  # fmt: skip
    print(f"{'mean B rotation':>22}: {r.median:.4f} rad  (80 % interval {r.low:.4f} to "
          f"{r.high:.4f} rad; linear model {r.linear:.4f} rad)")  # fmt: skip
    print(f"{'success probability':>22}: {p.success_probability:.2f}")
    for name, contrib in t.drivers:
        unit, _ = FEATURE_DOCS[name]
        value = p.features[name]
        word = "raises" if contrib > 0 else "lowers"
        print(f"{'driver':>22}: {name} = {value:.4g} {unit}".rstrip()
              + f"  ({word} the error by a factor {math.exp(abs(contrib)):.2f})")  # fmt: skip
    print(f"{'trained on':>22}: {p.trained_on}")
