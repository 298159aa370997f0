"""Batch experiments: worlds x seeds x SLAM algorithms x laser noise, expanded into keyed runs."""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from worker.errors import InputError
from worker.param_io import load_params_file
from worker.run_params import RunParams
from worker.slam import registry
from worker.world.catalogue import CATALOGUE_SUFFIXES, default_worlds_dir, find_worlds
from worker.world.loader import load_world
from worker.world.world import World

GROUP_KEYS = ("worlds", "runs", "seeds", "slam", "laser_noise", "params")
EXPERIMENT_KEYS = (*GROUP_KEYS, "name", "description", "groups")
_FURNITURE = re.compile(r"^(?P<base>.+?)_furnitures?$")
MAX_RUNS = 100_000  # a guard against a typo such as --seeds 1-1000000000


@dataclass(frozen=True)
class RunSpec:
    """One run of a batch and the labels its tables group it by."""

    key: str  # run identity: world content + name, full parameters, seed (see run_key)
    world_path: str  # absolute path of the floorplan file
    world: str  # world name
    base: str  # the world's name without a furniture suffix (pairs the two variants)
    variant: str  # "furniture" | "no_furniture"
    slam: str
    noise: float  # [m] laser range noise sigma
    seed: int
    params: dict[str, Any]  # RunParams.to_json()

    @property
    def label(self) -> str:
        """Short human label: `office_a seed 3 rbpf noise 0.1`."""
        return f"{self.world} seed {self.seed} {self.slam} noise {self.noise:g}"


@dataclass(frozen=True)
class Group:
    """One product of an experiment: every world with every seed, algorithm and noise level."""

    worlds: tuple[Path, ...]
    seeds: tuple[int, ...]
    slam: tuple[str, ...]
    laser_noise: tuple[float, ...]  # [m]
    params: dict[str, Any]  # parameter overrides (sim, slam, explore, eval sections)


def parse_seeds(text: str) -> tuple[int, ...]:
    """`"1-10"`, `"1,3,5"` or `"1-3,7"` to seeds in order, without repeats."""
    seeds: list[int] = []
    for part in str(text).split(","):
        part = part.strip()
        m = re.fullmatch(r"(\d+)\s*-\s*(\d+)", part)
        if m:
            a, b = int(m[1]), int(m[2])
            if b < a or b - a >= MAX_RUNS:
                raise InputError(
                    f"seed range {part!r} must be A-B with A <= B (at most {MAX_RUNS})"
                )
            seeds.extend(range(a, b + 1))
        elif part.isdigit():
            seeds.append(int(part))
        else:
            raise InputError(f"seeds must look like 1-10 or 1,3,5, not {text!r}")
    return tuple(dict.fromkeys(seeds))


def parse_list(text: str | Sequence[Any], what: str, conv: Callable[[Any], Any]) -> tuple:
    """A comma-separated option (or a YAML list) converted item by item."""
    items = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    out = []
    for item in items:
        try:
            out.append(conv(item))
        except (TypeError, ValueError):
            raise InputError(f"{what}: cannot read {item!r}") from None
    if not out:
        raise InputError(f"{what}: empty list")
    return tuple(dict.fromkeys(out))


def _slam(name: Any) -> str:
    if name not in registry.names():
        raise ValueError(name)
    return str(name)


def _noise(value: Any) -> float:
    v = float(value)
    if not v >= 0.0 or v == float("inf"):
        raise ValueError(value)
    return v


def resolve_worlds(entries: Sequence[str | Path], base_dir: Path | None = None) -> list[Path]:
    """World files, and every floorplan under each folder, in order and without repeats."""
    out: list[Path] = []
    for entry in entries:
        p = Path(entry)
        if not p.is_absolute() and base_dir is not None:
            p = base_dir / p
        if p.is_dir():
            found = find_worlds(p)
            if not found:
                raise InputError("no floorplan (.yaml, .world) in this folder", path=p)
            out.extend(found)
        elif p.is_file():
            if p.suffix.lower() not in CATALOGUE_SUFFIXES:
                raise InputError(
                    "a batch takes floorplan descriptions (.yaml, .world): give an image a "
                    "map_server YAML with its resolution",
                    path=p,
                )
            out.append(p)
        else:
            raise InputError("no such world file or folder", path=p)
    return list(dict.fromkeys(p.resolve() for p in out))


def merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    """Deep merge of parameter sections: `over` wins."""
    out = dict(base)
    for k, v in over.items():
        out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def thesis_experiment() -> dict[str, Any]:
    """The thesis's set on the bundled Bormann worlds: every world in both furniture variants,
    10 runs each, and the laser-noise sweep 0, 0.1, 0.3 m on two worlds (thesis 6.3.3 used
    office_d with furniture and a school plan we do not ship; Freiburg79 stands in for it)."""
    bormann = default_worlds_dir() / "bormann"
    sweep = [bormann / "office_d_furnitures.yaml", bormann / "Freiburg79_scan.yaml"]
    return {
        "name": "thesis",
        "description": "Bormann worlds, both variants, 10 runs each; noise sweep on two worlds",
        "runs": 10,
        "slam": ["rbpf"],
        "groups": [
            {"worlds": [str(bormann)], "laser_noise": [0.0]},
            {"worlds": [str(p) for p in sweep], "laser_noise": [0.0, 0.1, 0.3]},
        ],
    }


def load_experiment(name_or_path: str) -> tuple[dict[str, Any], Path | None]:
    """A bundled experiment by name, or an experiment YAML file, and the folder its relative
    world paths are read from."""
    if name_or_path == "thesis":
        return thesis_experiment(), None
    path = Path(name_or_path)
    if not path.is_file():
        raise InputError("no such experiment (bundled: thesis) or experiment file", path=path)
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, yaml.YAMLError) as exc:
        raise InputError(f"cannot read experiment file: {exc}", path=path) from None
    if not isinstance(raw, dict):
        raise InputError("an experiment file holds a mapping (worlds, runs, ...)", path=path)
    return raw, path.parent


def _check_keys(raw: dict[str, Any], allowed: Sequence[str], where: str) -> None:
    unknown = sorted(set(raw) - set(allowed))
    if unknown:
        raise InputError(f"{where}: unknown key {unknown[0]!r} (valid: {', '.join(allowed)})")


def _seeds_of(raw: dict[str, Any]) -> tuple[int, ...] | None:
    """The seeds one layer (experiment, group, options) asks for, if it asks."""
    if raw.get("seeds") is not None and raw.get("runs") is not None:
        raise InputError("give runs or seeds, not both")
    if raw.get("seeds") is not None:
        s = raw["seeds"]
        if isinstance(s, int | str) and not isinstance(s, bool):
            return parse_seeds(str(s))
        if not isinstance(s, list) or not all(type(v) is int and v >= 0 for v in s):
            raise InputError(f"seeds must be A-B, a list of whole numbers, not {s!r}")
        return tuple(dict.fromkeys(s))
    if raw.get("runs") is not None:
        n = raw["runs"]
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= MAX_RUNS:
            raise InputError(f"runs must be a whole number from 1 to {MAX_RUNS}, not {n!r}")
        return tuple(range(1, n + 1))
    return None


def build_groups(
    raw: dict[str, Any], base_dir: Path | None, overrides: dict[str, Any], base_params: dict
) -> list[Group]:
    """The experiment's groups with command-line `overrides` (the same keys as a group) applied
    on top of each; `base_params` (a --params file) sits between the experiment's and the
    options'. Lists default to one run, the parameters' own algorithm and noise."""
    _check_keys(raw, EXPERIMENT_KEYS, "experiment")
    top = {k: raw[k] for k in GROUP_KEYS if k in raw}
    groups = raw.get("groups") or [{}]
    if not isinstance(groups, list):
        raise InputError("experiment: groups must be a list of mappings")
    out = []
    for i, g in enumerate(groups):
        if not isinstance(g, dict):
            raise InputError(f"experiment: groups[{i}] must be a mapping")
        _check_keys(g, GROUP_KEYS, f"experiment groups[{i}]")
        opts = {k: v for k, v in overrides.items() if v is not None}
        spec = {**top, **g, **opts}
        spec["seeds"] = _seeds_of(opts) or _seeds_of(g) or _seeds_of(top) or (1,)
        out.append(_group(spec, base_dir, base_params))
    return out


def _group(spec: dict[str, Any], base_dir: Path | None, base_params: dict) -> Group:
    if not spec.get("worlds"):
        raise InputError("no worlds given (WORLDS arguments or the experiment's worlds list)")
    worlds = spec["worlds"]
    worlds = [worlds] if isinstance(worlds, str) else worlds
    params = spec.get("params") or {}
    if not isinstance(params, dict):
        raise InputError("experiment: params must be a mapping of sections")
    params = merge(params, base_params)
    defaults = RunParams.from_json(params)  # validates early, with the key named
    slam = spec.get("slam") or [defaults.algorithm]
    noise = spec.get("laser_noise")
    noise = [defaults.sim.laser_noise_sigma] if noise is None else noise
    return Group(
        worlds=tuple(resolve_worlds(worlds, base_dir)),
        seeds=spec["seeds"],
        slam=parse_list(slam, f"slam ({', '.join(registry.names())})", _slam),
        laser_noise=parse_list(noise, "laser noise [m] (>= 0)", _noise),
        params=params,
    )


def world_fingerprint(world: World) -> str:
    """Content hash of a loaded world (see `World.fingerprint`)."""
    return world.fingerprint()


def run_key(fingerprint: str, name: str, params: dict[str, Any], seed: int) -> str:
    """A run's identity: same world, parameters and seed give the same run, bit for bit, so a
    finished run with this key never needs doing again (resuming skips it)."""
    doc = json.dumps([fingerprint, name, params, int(seed)], sort_keys=True, allow_nan=False)
    return hashlib.sha256(doc.encode()).hexdigest()[:20]


def variant_of(name: str) -> tuple[str, str]:
    """(base, variant): Bormann names a furnished world `<base>_furnitures`."""
    m = _FURNITURE.match(name)
    return (m["base"], "furniture") if m else (name, "no_furniture")


def expand(
    groups: Sequence[Group], loader: Callable[[Path], World] = load_world
) -> tuple[list[RunSpec], dict[str, World]]:
    """Every run of the experiment, each once, ordered seed-major (early results span every
    world), and the loaded worlds by path."""
    worlds: dict[str, World] = {}
    specs: dict[str, RunSpec] = {}
    for g in groups:
        for path in g.worlds:
            if str(path) not in worlds:
                worlds[str(path)] = loader(path)
        for seed in g.seeds:
            for path in g.worlds:
                world = worlds[str(path)]
                fp = world_fingerprint(world)
                base, variant = variant_of(world.name)
                for slam in g.slam:
                    for noise in g.laser_noise:
                        over = {"algorithm": slam, "sim": {"laser_noise_sigma": noise}}
                        run_params = RunParams.from_json(merge(g.params, over))
                        params = run_params.to_json()
                        key = run_key(fp, world.name, params, seed)
                        name = registry.label(slam, run_params.slam)  # external:NAME
                        specs.setdefault(
                            key,
                            RunSpec(key, str(path), world.name, base, variant, name, noise,
                                    seed, params),
                        )  # fmt: skip
    if len(specs) > MAX_RUNS:
        raise InputError(f"the experiment has {len(specs)} runs, more than {MAX_RUNS}")
    return list(specs.values()), worlds


def load_params(path: Path | None) -> dict[str, Any]:
    """A --params file's sections, or nothing."""
    return load_params_file(path) if path is not None else {}
