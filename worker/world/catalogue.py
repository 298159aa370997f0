"""The worlds catalogue: find the floorplans under a folder and summarise them."""

from __future__ import annotations

from pathlib import Path

from worker.errors import InputError
from worker.world.loader import load_world
from worker.world.world import World

CATALOGUE_SUFFIXES = (".yaml", ".yml", ".world")


def default_worlds_dir() -> Path:
    """`./worlds` when it exists, else the `worlds/` folder of the mapqual checkout."""
    here = Path("worlds")
    if here.is_dir():
        return here
    return Path(__file__).resolve().parents[2] / "worlds"


def find_worlds(folder: str | Path) -> list[Path]:
    """Floorplan descriptions (map_server YAML, Stage .world) under `folder`, sorted by path.

    Bare images are not listed: they need a resolution, which a YAML supplies.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("no such folder", path=folder)
    found = [p for p in folder.rglob("*") if p.suffix.lower() in CATALOGUE_SUFFIXES and p.is_file()]
    return sorted(found, key=lambda p: str(p.relative_to(folder)).lower())


def load_catalogue(folder: str | Path) -> list[World]:
    """Load every world under `folder` (an unreadable one raises InputError naming it)."""
    return [load_world(p) for p in find_worlds(folder)]
