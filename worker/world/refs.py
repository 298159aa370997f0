"""Files a floorplan description refers to (map_server `image:`/`segmentation:`, Stage
`bitmap`), resolved and confined to the describing file's folder.

Cheap on purpose (YAML and Stage parsing, no pixel decoded, no numba): the API checks an
upload with it in the request, before the analysis runs elsewhere.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from worker.errors import InputError
from worker.world.image_io import MAX_PIXELS, image_size
from worker.world.stage import StageMap, read_stage_world


def referenced_file(owner: Path, key: str, value: object, *, allow_outside: bool = False) -> Path:
    """The file that `owner`'s `key: value` names, relative to `owner`'s folder.

    After symlinks are followed it must lie under that folder: an absolute path, `../` or a
    link pointing out would let a floorplan read any image on the machine (in the API,
    another owner's maps). InputError names the key and the value unless `allow_outside`.
    """
    text = str(value)
    if not text.strip() or "\0" in text:
        raise InputError(f"`{key}` {text!r} is not a file name", path=owner)
    folder = owner.parent.resolve()
    target = (owner.parent / text).resolve()
    if not allow_outside and not target.is_relative_to(folder):
        raise InputError(
            f"`{key}` {text!r} lies outside this file's folder (refused; --allow-outside "
            "permits it on the command line)",
            path=owner,
        )
    if target.is_dir():  # e.g. `image: .`: said so, the folder's path not shown
        raise InputError(f"`{key}` {text!r} names a folder, not a file", path=owner)
    return target


def read_map_yaml(path: Path) -> dict[str, Any]:
    """The mapping of a map_server YAML file; InputError if it is none or has no `image:`."""
    try:
        meta = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None
    except yaml.YAMLError as exc:
        line = getattr(getattr(exc, "problem_mark", None), "line", None)
        raise InputError(
            "not valid YAML", path=path, line=None if line is None else line + 1
        ) from None
    if not isinstance(meta, dict) or "image" not in meta:
        raise InputError("not a map_server YAML (no `image:` key)", path=path)
    return meta


def yaml_references(
    path: Path, meta: dict[str, Any], *, allow_outside: bool = False
) -> dict[str, Path]:
    """`image` (and `segmentation`, when given) of a map_server YAML, confined."""
    refs = {"image": referenced_file(path, "image", meta["image"], allow_outside=allow_outside)}
    if meta.get("segmentation"):
        refs["segmentation"] = referenced_file(
            path, "segmentation", meta["segmentation"], allow_outside=allow_outside
        )
    return refs


def stage_references(path: Path, *, allow_outside: bool = False) -> tuple[StageMap, Path]:
    """A Stage `.world` file's map and its `bitmap`, confined."""
    stage = read_stage_world(path)
    return stage, referenced_file(path, "bitmap", stage.bitmap_ref, allow_outside=allow_outside)


def floorplan_images(path: Path, *, allow_outside: bool = False) -> dict[str, Path]:
    """Every image a floorplan file reads, by key (`file` for a bare image), confined."""
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        return yaml_references(path, read_map_yaml(path), allow_outside=allow_outside)
    if suffix == ".world":
        return {"bitmap": stage_references(path, allow_outside=allow_outside)[1]}
    return {"file": path}


def check_resolution(resolution: object, source: str | Path | None) -> None:
    """Resolution must be a finite number in (0.005, 1] m/pixel."""
    try:
        r = float(resolution)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"resolution must be a number, got {resolution!r}", path=source) from None
    if not math.isfinite(r) or not (0.005 < r <= 1.0):
        raise InputError(f"resolution {r:g} m/pixel is outside (0.005, 1] m", path=source)


def check_floorplan(
    path: Path, resolution: float | None, max_pixels: int = MAX_PIXELS
) -> dict[str, tuple[int, int]]:
    """What can be refused without decoding a pixel: references (confined), the resolution,
    and each image's header (ImageTooLarge past `max_pixels`). `(width, height)` by key."""
    images = floorplan_images(path)
    if resolution is not None:
        check_resolution(resolution, path)
    elif "file" in images:
        raise InputError("an image needs its resolution in m/pixel (--resolution)", path=path)
    elif "image" in images:
        meta = read_map_yaml(path)
        if "resolution" not in meta:
            raise InputError("no `resolution:` key (or give --resolution)", path=path)
        check_resolution(meta["resolution"], path)
    return {key: image_size(image, max_pixels) for key, image in images.items()}
