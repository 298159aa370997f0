"""The flat `explore` keys of before the groups (issue 53): which group each belongs to, and
the conversion that lets stored runs, parameter files and jobs written that way load."""

from __future__ import annotations

import dataclasses
from dataclasses import fields
from typing import Any

from worker.errors import InputError
from worker.explore.params import ExploreParams
from worker.param_io import from_dict

GROUPS: tuple[str, ...] = tuple(
    f.name for f in fields(ExploreParams) if dataclasses.is_dataclass(f.default_factory)
)


def _group_of_flat_key() -> dict[str, str]:
    groups = {name: getattr(ExploreParams(), name) for name in GROUPS}
    return {f.name: name for name, group in groups.items() for f in fields(group)}


FLAT_KEYS: dict[str, str] = _group_of_flat_key()  # flat key of before the groups -> its group


def nest_flat(data: Any) -> Any:
    """An `explore` mapping with the flat keys of before the groups (`{"door_align": true}`)
    moved into their groups (`{"doors": {"door_align": true}}`); nested keys, the loop's own
    and unknown keys stay where they are (an unknown key is refused when the mapping is read).
    A key given both ways raises InputError."""
    if not isinstance(data, dict) or not any(k in FLAT_KEYS for k in data):
        return data
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in data.items() if k not in FLAT_KEYS}
    for key, value in data.items():
        group = FLAT_KEYS.get(key)
        if group is None:
            continue
        inner = out.setdefault(group, {})
        if not isinstance(inner, dict):
            continue  # refused when read: the group must be a mapping
        if key in inner:
            raise InputError(f"explore.{key} is given twice (flat and in explore.{group})")
        inner[key] = value
    return out


def explore_params(**values: Any) -> ExploreParams:
    """ExploreParams from keyword values, by group (`doors={"door_align": True}`) or flat as
    before the groups (`door_align=True`), strictly checked as a parameter file is."""
    return from_dict(ExploreParams, nest_flat(values), "explore")
