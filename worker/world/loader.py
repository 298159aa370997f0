"""Load a World from an image + resolution, a ROS map_server YAML, or a Stage `.world` file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from worker.errors import InputError
from worker.robot import FOOTPRINT_M
from worker.world.floorplan import Floorplan
from worker.world.image_io import MAX_PIXELS, read_grey
from worker.world.refs import (
    check_resolution,
    read_map_yaml,
    stage_references,
    yaml_references,
)
from worker.world.world import World

FREE_GREY_MIN = 250  # default rule: grey >= 250 is free, anything else is an obstacle
IMAGE_SUFFIXES = {".png", ".pgm", ".ppm", ".pbm", ".bmp", ".gif", ".tif", ".tiff", ".jpg", ".jpeg"}


def load_world(
    path: str | Path,
    resolution: float | None = None,
    *,
    start_pose: tuple[float, float, float] | None = None,
    segmentation: str | Path | None = None,
    max_pixels: int = MAX_PIXELS,
    footprint_m: float = FOOTPRINT_M,
    allow_outside: bool = False,
) -> World:
    """Load a floorplan: `.yaml` (map_server), `.world` (Stage) or an image plus `resolution`.

    `resolution` [m/pixel] overrides the file's own. A `segmentation` image (Bormann's
    gt_segmentation style) adds a room count; a map_server YAML may name one with the extra
    key `segmentation:`. Files a YAML or `.world` names must lie under its folder unless
    `allow_outside` (see `worker.world.refs`). Raises InputError on any bad input.
    """
    plan = read_floorplan(
        path, resolution, start_pose=start_pose, segmentation=segmentation,
        max_pixels=max_pixels, allow_outside=allow_outside,
    )  # fmt: skip
    return build_world(plan, footprint_m)


def read_floorplan(
    path: str | Path,
    resolution: float | None = None,
    *,
    start_pose: tuple[float, float, float] | None = None,
    segmentation: str | Path | None = None,
    max_pixels: int = MAX_PIXELS,
    allow_outside: bool = False,
) -> Floorplan:
    """The floorplan's files read (what `load_world` reads, nothing analysed yet)."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file", path=path)
    if path.is_dir():
        raise InputError("is a folder, not a floorplan file", path=path)
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        return _read_yaml(path, resolution, start_pose, segmentation, max_pixels, allow_outside)
    if suffix == ".world":
        return _read_stage(path, resolution, start_pose, segmentation, max_pixels, allow_outside)
    if resolution is None:
        raise InputError("an image needs its resolution in m/pixel (--resolution)", path=path)
    grey, alpha = read_grey(path, max_pixels)
    notes = []
    free = grey >= FREE_GREY_MIN
    if alpha is not None:
        free &= alpha >= 128
        notes.append("transparent pixels count as obstacles")
    return _plan(
        path.stem, free, resolution, (0.0, 0.0), start_pose, segmentation, path, max_pixels,
        notes,
    )  # fmt: skip


def build_world(plan: Floorplan, footprint_m: float = FOOTPRINT_M) -> World:
    """The World of a read floorplan: free regions, clearance, start pose, facts."""
    try:
        return World.from_array(
            plan.occ, plan.resolution, plan.origin, plan.start_pose, plan.name,
            footprint_m=footprint_m, n_rooms=plan.n_rooms, warnings=plan.notes,
            source=plan.source,
        )  # fmt: skip
    except InputError as exc:
        if exc.path is not None:
            raise
        raise InputError(str(exc), path=plan.source) from None


def _plan(
    name, free_img, resolution, origin, start_pose, segmentation, source, max_pixels, notes
) -> Floorplan:
    """Flip the image rows to the grid's bottom-first order, count rooms."""
    check_resolution(resolution, source)
    occ = np.flipud(~free_img)
    n_rooms = None
    if segmentation is not None:
        from worker.world.segmentation import count_rooms

        n_rooms = count_rooms(Path(segmentation), float(resolution), occ.shape, max_pixels)
    return Floorplan(
        name=name, occ=occ, resolution=float(resolution),
        origin=(float(origin[0]), float(origin[1])),
        start_pose=None if start_pose is None else tuple(float(v) for v in start_pose),
        n_rooms=n_rooms, notes=tuple(notes), source=str(source),
    )  # fmt: skip


def _read_yaml(path, resolution, start_pose, segmentation, max_pixels, allow_outside) -> Floorplan:
    """ROS map_server YAML: image, resolution, origin, negate, occupied_thresh, free_thresh."""
    meta = read_map_yaml(path)
    refs = yaml_references(path, meta, allow_outside=allow_outside)
    if resolution is None:
        if "resolution" not in meta:
            raise InputError("no `resolution:` key (or give --resolution)", path=path)
        resolution = meta["resolution"]
    check_resolution(resolution, path)
    origin, negate, free_thresh = _yaml_thresholds(meta, path)
    notes = []
    mode = str(meta.get("mode", "trinary"))
    if mode != "trinary":
        notes.append(f"map_server mode {mode!r} is read as trinary (free / obstacle)")
    if len(origin) > 2 and origin[2] != 0.0:
        notes.append("the YAML origin's yaw is ignored (as most map_server users do)")
    grey, alpha = read_grey(refs["image"], max_pixels)
    free = _map_server_free(grey, negate, free_thresh)
    if alpha is not None:
        free &= alpha >= 128
        notes.append("transparent pixels count as obstacles")
    if segmentation is None and "segmentation" in refs:
        segmentation = refs["segmentation"]
    return _plan(
        path.stem, free, resolution, (origin[0], origin[1]), start_pose, segmentation, path,
        max_pixels, notes,
    )  # fmt: skip


def _yaml_thresholds(meta: dict, path: Path) -> tuple[list[float], int, float]:
    """(origin [x, y(, yaw)], negate, free_thresh) of a map_server YAML, checked."""
    origin = meta.get("origin", [0.0, 0.0, 0.0])
    try:
        origin = [float(v) for v in origin]
        negate = int(meta.get("negate", 0))
        occupied_thresh = float(meta.get("occupied_thresh", 0.65))
        free_thresh = float(meta.get("free_thresh", 0.196))
    except (TypeError, ValueError):
        raise InputError(
            "origin/negate/occupied_thresh/free_thresh must be numbers", path=path
        ) from None
    if not (0.0 <= free_thresh <= occupied_thresh <= 1.0):
        raise InputError(
            f"need 0 <= free_thresh ({free_thresh:g}) <= occupied_thresh "
            f"({occupied_thresh:g}) <= 1",
            path=path,
        )
    if len(origin) < 2 or not all(math.isfinite(v) for v in origin):
        raise InputError("origin must be [x, y, yaw]", path=path)
    return origin, negate, free_thresh


def _map_server_free(grey: np.ndarray, negate: int, free_thresh: float) -> np.ndarray:
    """(H, W) bool free pixels of a uint8 image by map_server's trinary rule."""
    # map_server: p = (255 - grey) / 255 is the occupancy probability (grey inverted if negate);
    # free if p < free_thresh, occupied if p > occupied_thresh, unknown between. Unknown is not
    # free space for the robot, so it counts as an obstacle here. Grey is uint8, so the rule is
    # a table of its 256 levels: no float image is ever made.
    levels = np.arange(256, dtype=np.float64)
    if negate:
        levels = 255.0 - levels
    return ((255.0 - levels) / 255.0 < free_thresh)[grey]


def _read_stage(path, resolution, start_pose, segmentation, max_pixels, allow_outside) -> Floorplan:
    """Stage `.world`: bitmap scaled to `size`, centred on the block's `pose`; robot pose."""
    stage, bitmap = stage_references(path, allow_outside=allow_outside)
    grey, alpha = read_grey(bitmap, max_pixels)
    h, w = grey.shape
    res_x, res_y = stage.size[0] / w, stage.size[1] / h
    if resolution is None:
        if abs(res_x - res_y) > 0.02 * max(res_x, res_y):
            raise InputError(
                f"size {stage.size[0]:g} x {stage.size[1]:g} m over {w} x {h} pixels gives "
                f"non-square pixels ({res_x:.4f} vs {res_y:.4f} m)",
                path=path,
            )
        resolution = 0.5 * (res_x + res_y)
    free = grey >= FREE_GREY_MIN
    notes = []
    if alpha is not None:
        free &= alpha >= 128
        notes.append("transparent pixels count as obstacles")
    # Stage turns the model (and its bitmap) about its centre by the pose's yaw; np.rot90
    # turns an image (top row first) counter-clockwise as seen.
    free = np.rot90(free, stage.quarter_turns)
    h, w = free.shape
    origin = (stage.center[0] - 0.5 * w * resolution, stage.center[1] - 0.5 * h * resolution)
    if start_pose is None:
        start_pose = stage.robot_pose
    return _plan(
        path.stem, free, resolution, origin, start_pose, segmentation, path, max_pixels, notes
    )
