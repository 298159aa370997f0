"""`mapqual world info|list`: floorplan facts, start pose and warnings; the worlds catalogue."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Annotated

import typer

from mapqual.cli import app

world_app = typer.Typer(
    rich_markup_mode=None,
    help="Floorplans: facts, start pose and the worlds catalogue.",
    no_args_is_help=True,
)
app.add_typer(world_app, name="world")

ResolutionOpt = Annotated[
    float | None,
    typer.Option(help="Metres per pixel (needed for a bare image; overrides a YAML's)."),
]
JsonOpt = Annotated[bool, typer.Option("--json", help="Print one JSON object.")]
# Every command that loads a world takes this: a YAML's `image:`/`segmentation:` or a .world's
# `bitmap` naming a file outside the describing file's folder is refused without it.
AllowOutsideOpt = Annotated[
    bool,
    typer.Option(
        "--allow-outside",
        help="Let a YAML or .world refer to images outside its own folder (../, absolute "
        "paths, links pointing out).",
    ),
]


def world_summary(world) -> dict:
    """The facts, start pose and warnings of a World as a JSON-ready dict."""
    return {
        "name": world.name,
        "source": world.source,
        **dataclasses.asdict(world.facts),
        "origin": [float(v) for v in world.origin],
        "start_pose": [round(float(v), 6) for v in world.start_pose],
        "warnings": list(world.warnings),
    }


@world_app.command("info")
def info(
    world: Annotated[Path, typer.Argument(help="Image, map_server YAML or Stage .world file.")],
    resolution: ResolutionOpt = None,
    segmentation: Annotated[
        Path | None, typer.Option(help="Segmentation image (doorway lines) for a room count.")
    ] = None,
    max_pixels: Annotated[int, typer.Option(help="Refuse larger images.")] = 64_000_000,
    as_json: JsonOpt = False,
    allow_outside: AllowOutsideOpt = False,
) -> None:
    """Facts about a floorplan: size, free area, regions, clearance, rooms, start pose."""
    from worker.world import load_world

    w = load_world(
        world,
        resolution,
        segmentation=segmentation,
        max_pixels=max_pixels,
        allow_outside=allow_outside,
    )
    summary = world_summary(w)
    features, why = _features(w, segmentation, allow_outside)
    if as_json:
        print(json.dumps({**summary, "features": features, "features_error": why}))
        return
    f = w.facts
    rooms = "-" if f.n_rooms is None else str(f.n_rooms)
    x, y, th = w.start_pose
    lines = [
        ("world", f"{w.name}  ({w.source})"),
        (
            "size",
            f"{f.width_m:.2f} m x {f.height_m:.2f} m  ({f.width_px} x {f.height_px} px "
            f"at {f.resolution:g} m/px)",
        ),
        ("origin", f"({w.origin[0]:g}, {w.origin[1]:g}) m"),
        ("free area", f"{f.free_area_m2:.1f} m^2  ({100 * f.free_fraction:.1f} % of the image)"),
        (
            "free regions",
            f"{f.n_free_regions}; the main one has {f.largest_region_area_m2:.1f}"
            f" m^2 ({100 * f.largest_region_share:.1f} % of the free area)",
        ),
        (
            "clearance",
            f"mean {f.clearance_mean_m:.2f} m, median {f.clearance_median_m:.2f} m, "
            f"p90 {f.clearance_p90_m:.2f} m, max {f.clearance_max_m:.2f} m",
        ),
        ("rooms", rooms),
        ("start pose", f"x {x:.3f} m, y {y:.3f} m, theta {th:.3f} rad"),
    ]
    for key, value in lines:
        print(f"{key:>13}: {value}")
    for warning in w.warnings:
        print(f"{'warning':>13}: {warning}")
    _print_features(features, why)


def _features(w, segmentation: Path | None, allow_outside: bool) -> tuple[dict | None, str | None]:
    """(the floorplan features as a dict, None) or (None, why there are none)."""
    from worker.errors import InputError
    from worker.world.features import segmentation_rooms, world_features

    try:
        seg = segmentation_rooms(w, segmentation, allow_outside=allow_outside)
        return world_features(w, seg).as_dict(), None
    except InputError as exc:
        return None, str(exc)


def _print_features(features: dict | None, why: str | None) -> None:
    """The features, one a line: name, value and unit, meaning."""
    from worker.world.features import FEATURE_DOCS

    print("features:" if features else f"features: none ({why})")
    for name, value in (features or {}).items():
        unit, meaning = FEATURE_DOCS[name]
        text = f"{value:.4g}" if isinstance(value, float) else str(value)
        print(f"  {name:<27} {text:>10} {unit:<9} {meaning}")


@world_app.command("list")
def list_worlds(
    folder: Annotated[
        Path | None, typer.Argument(help="Folder to scan (default: ./worlds, else mapqual's).")
    ] = None,
    as_json: JsonOpt = False,
    allow_outside: AllowOutsideOpt = False,
) -> None:
    """The worlds catalogue: every map_server YAML and Stage .world under a folder."""
    from worker.world.catalogue import default_worlds_dir, find_worlds
    from worker.world.loader import load_world

    folder = folder or default_worlds_dir()
    paths = find_worlds(folder)
    if as_json:
        worlds = [load_world(p, allow_outside=allow_outside) for p in paths]
        print(json.dumps([world_summary(w) for w in worlds]))
        return
    header = (
        f"{'world':<28} {'w x h [m]':>13} {'free [m2]':>9} {'free':>6} {'regions':>7} "
        f"{'rooms':>5} {'clear [m]':>9}  {'start pose [m, m, rad]':<24} warnings"
    )
    print(header)
    for p in paths:
        w = load_world(p, allow_outside=allow_outside)
        f = w.facts
        size = f"{f.width_m:.1f} x {f.height_m:.1f}"
        start = "{:.2f}, {:.2f}, {:.2f}".format(*w.start_pose)
        rooms = "-" if f.n_rooms is None else str(f.n_rooms)
        print(
            f"{w.name:<28} {size:>13} {f.free_area_m2:>9.1f} {100 * f.free_fraction:>5.1f}% "
            f"{f.n_free_regions:>7} {rooms:>5} {f.clearance_mean_m:>9.2f}  {start:<24} "
            f"{len(w.warnings)}"
        )
    print(f"{len(paths)} worlds in {folder}")


@world_app.command("generate")
def generate_cmd(
    kind: Annotated[str, typer.Argument(help="warehouse (aisles of racks) or hospital (wards).")],
    out: Annotated[Path, typer.Option("-o", "--out", help="Folder for NAME.png and NAME.yaml.")],
    width: Annotated[float, typer.Option(help="Outer width [m] (x).")] = 200.0,
    height: Annotated[float, typer.Option(help="Outer height [m] (y).")] = 100.0,
    seed: Annotated[int, typer.Option(help="Places racks, rooms, doors and pallets.")] = 1,
    resolution: Annotated[float, typer.Option(help="Metres per pixel.")] = 0.05,
    name: Annotated[str | None, typer.Option(help="File stem (default: KIND_WxH_sSEED).")] = None,
) -> None:
    """A seeded large building (warehouse or hospital wing) as a map_server world."""
    from worker.world.generate import BuildingSpec, generate, write_world

    spec = BuildingSpec(kind, width, height, seed, resolution)  # type: ignore[arg-type]
    img = generate(spec)
    stem = name or f"{kind}_{width:g}x{height:g}_s{seed}"
    path = write_world(img, spec, out, stem)
    print(f"{path}  ({img.shape[1]} x {img.shape[0]} px, {img.size:,} cells)")
