"""Bundled data sets: each sub-folder of a worlds folder (`worlds/bormann`, `worlds/schools`)
with its licence file, an optional `dataset.json` (title, licence in a few words), and its
worlds summarised once: facts, start pose, content hash and a packed occupancy grid for
pictures. Loading a data set loads every world in it (about 0.1 s each); callers keep it."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from worker.errors import InputError
from worker.world.catalogue import find_worlds
from worker.world.loader import load_world
from worker.world.world import World, WorldFacts

META_FILE = "dataset.json"
# the file that says where a data set comes from and under which licence, first found wins
LICENCE_FILES = (
    "LICENSE", "LICENSE.md", "LICENSE.txt", "LICENCE", "LICENCE.md", "COPYING", "SOURCE.md",
    "README.md",
)  # fmt: skip
MAX_TEXT = 200  # [characters] of a title or a licence summary from dataset.json


@dataclass(frozen=True)
class BundledWorld:
    """One world of a data set as loaded (`load_world`), without its large arrays."""

    name: str  # its file's path under the data set's folder, without the suffix: `office_a`
    path: Path  # the map_server YAML or Stage .world
    source_format: Literal["yaml", "stage"]
    facts: WorldFacts
    warnings: tuple[str, ...]
    origin: tuple[float, float]  # [m] the grid's lower-left corner
    start_pose: tuple[float, float, float]  # [m, m, rad]
    fingerprint: str  # World.fingerprint(): the sha256 a stored copy of it has
    shape: tuple[int, int]  # (H, W) cells
    occ_bits: bytes = field(repr=False)  # np.packbits of occ (H, W) bool, bottom row first

    @classmethod
    def of(cls, name: str, path: Path, world: World) -> BundledWorld:
        return cls(
            name=name,
            path=path,
            source_format="stage" if path.suffix.lower() == ".world" else "yaml",
            facts=world.facts,
            warnings=tuple(world.warnings),
            origin=(float(world.origin[0]), float(world.origin[1])),
            start_pose=tuple(float(v) for v in world.start_pose),
            fingerprint=world.fingerprint(),
            shape=(int(world.occ.shape[0]), int(world.occ.shape[1])),
            occ_bits=np.packbits(np.asarray(world.occ, dtype=bool)).tobytes(),
        )

    def occupancy(self) -> np.ndarray:
        """The occupancy grid `(H, W) bool`, True = obstacle, bottom row first."""
        h, w = self.shape
        bits = np.unpackbits(np.frombuffer(self.occ_bits, dtype=np.uint8), count=h * w)
        return bits.reshape(h, w).astype(bool)

    def facts_dict(self) -> dict[str, Any]:
        """The facts as a stored world has them, with the loader's warnings."""
        return {**dataclasses.asdict(self.facts), "warnings": list(self.warnings)}


@dataclass(frozen=True)
class Dataset:
    """A folder of floorplans with the file that names their source and licence."""

    name: str  # the folder's name: `bormann`
    folder: Path
    title: str
    licence: str | None  # in a few words, from dataset.json
    licence_file: str | None  # a file in the folder (LICENCE_FILES, or dataset.json's choice)
    worlds: tuple[BundledWorld, ...]
    problems: tuple[str, ...] = ()  # worlds that did not load, one line each

    def world(self, name: str) -> BundledWorld | None:
        """The world called `name`, if the data set has it (names are compared, never opened)."""
        return next((w for w in self.worlds if w.name == name), None)

    def licence_text(self) -> str | None:
        """The licence file's text."""
        if self.licence_file is None:
            return None
        return (self.folder / self.licence_file).read_text(encoding="utf-8", errors="replace")


def dataset_folders(root: str | Path) -> list[Path]:
    """The sub-folders of `root` that hold a floorplan description, sorted by name (hidden
    folders left out; plans directly in `root` belong to no data set)."""
    root = Path(root)
    if not root.is_dir():
        return []
    subs = sorted(
        (p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")),
        key=lambda p: p.name.lower(),
    )
    return [p for p in subs if find_worlds(p)]


def folder_signature(folder: Path) -> tuple[tuple[str, int, int], ...]:
    """(path, mtime [ns], size [bytes]) of every file under `folder`: what a data set loaded
    from it depends on (a changed image changes its world as surely as a changed YAML)."""
    out = []
    for p in folder.rglob("*"):
        if p.is_file():
            st = p.stat()
            out.append((str(p.relative_to(folder)), st.st_mtime_ns, st.st_size))
    return tuple(sorted(out))


def load_dataset(folder: str | Path) -> Dataset:
    """Load every world of the data set in `folder`; a world that does not load is left out
    and named in `problems` (one bad file does not hide the others)."""
    folder = Path(folder).resolve()
    meta = _meta(folder)
    worlds, problems = [], []
    for path in find_worlds(folder):
        name = path.relative_to(folder).with_suffix("").as_posix()
        try:
            worlds.append(BundledWorld.of(name, path, load_world(path)))
        except InputError as exc:
            where = str(path.relative_to(folder))
            msg = str(exc).replace(str(folder) + "/", "")
            problems.append(msg if msg.startswith(where + ":") else f"{where}: {msg}")
    return Dataset(
        name=folder.name,
        folder=folder,
        title=_text(meta.get("title")) or folder.name,
        licence=_text(meta.get("licence")),
        licence_file=_licence_file(folder, meta.get("licence_file")),
        worlds=tuple(worlds),
        problems=tuple(problems),
    )


def _meta(folder: Path) -> dict[str, Any]:
    """The data set's dataset.json, or nothing."""
    path = folder / META_FILE
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"not a readable JSON file ({exc})", path=path) from None
    if not isinstance(meta, dict):
        raise InputError("must hold a JSON object", path=path)
    return meta


def _text(value: Any) -> str | None:
    return " ".join(value.split())[:MAX_TEXT] if isinstance(value, str) and value.strip() else None


def _licence_file(folder: Path, named: Any) -> str | None:
    """dataset.json's `licence_file` (a file directly in the folder), else the first of
    LICENCE_FILES there."""
    candidates = ([named] if isinstance(named, str) else []) + list(LICENCE_FILES)
    for name in candidates:
        if Path(name).name == name and (folder / name).is_file():
            return name
    return None
