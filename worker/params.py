"""Frozen parameter dataclasses to and from JSON/YAML, strictly: unknown keys and wrong types
are errors that say which key and what was expected (the API and the CLI show them as is)."""

from __future__ import annotations

import dataclasses
import json
import math
import types
import typing
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

import yaml

from worker.errors import InputError

T = TypeVar("T")


def to_dict(obj: Any) -> dict[str, Any]:
    """A parameter dataclass as plain JSON-serialisable data (tuples become lists); a field
    whose metadata says `omit_if_none` is left out while it is None."""
    return json.loads(json.dumps(_omit_none(obj, dataclasses.asdict(obj))))


def _omit_none(obj: Any, data: dict[str, Any]) -> dict[str, Any]:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if value is None and f.metadata.get("omit_if_none"):
            del data[f.name]
        elif dataclasses.is_dataclass(value) and not isinstance(value, type):
            _omit_none(value, data[f.name])
    return data


def from_dict(cls: type[T], data: Any, where: str = "") -> T:
    """Build the dataclass `cls` from `data`, keeping defaults for keys that are absent.

    Raises `InputError` naming the dotted key (`slam.particles`) on an unknown key, a wrong type,
    a value outside a `Literal`'s choices, or a non-finite number.
    """
    prefix = f"{where}." if where else ""
    if not isinstance(data, dict):
        raise InputError(f"{where or 'parameters'} must be a mapping, not {type(data).__name__}")
    hints = get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise InputError(
            f"unknown parameter {prefix}{unknown[0]} (valid: {', '.join(sorted(fields))})"
        )
    kwargs = {k: _convert(hints[k], v, f"{prefix}{k}") for k, v in data.items()}
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:  # __post_init__ validation
        raise InputError(f"{where or 'parameters'}: {exc}") from None


def _convert(tp: Any, value: Any, key: str) -> Any:
    origin = get_origin(tp)
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, key)
    if origin is Literal:
        choices = get_args(tp)
        if value not in choices:
            raise InputError(f"{key} must be one of {', '.join(map(repr, choices))}, not {value!r}")
        return value
    if origin in (typing.Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return _convert(arg, value, key)
            except InputError as exc:
                errors.append(str(exc))
        raise InputError(errors[0])
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, list | tuple):
            raise InputError(f"{key} must be a list, not {type(value).__name__}")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, f"{key}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise InputError(f"{key} must have {len(args)} elements, not {len(value)}")
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_convert(a, v, f"{key}[{i}]") for i, (a, v) in pairs)
    if tp is bool:
        if not isinstance(value, bool):
            raise InputError(f"{key} must be true or false, not {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"{key} must be an integer, not {value!r}")
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InputError(f"{key} must be a number, not {value!r}")
        if not math.isfinite(value):
            raise InputError(f"{key} must be a finite number, not {value!r}")
        return float(value)
    if tp is str:
        if not isinstance(value, str):
            raise InputError(f"{key} must be a string, not {value!r}")
        return value
    raise InputError(f"{key}: unsupported parameter type {tp!r}")


def load_params_file(path: str | Path) -> dict[str, Any]:
    """Read a YAML or JSON parameter file into a mapping (`sim:`, `slam:`, ... sections)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise InputError(f"cannot read parameter file: {exc.strerror}", path=p) from None
    try:
        data = json.loads(text) if p.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        line = getattr(exc, "lineno", None)
        mark = getattr(exc, "problem_mark", None)
        if mark is not None:
            line = mark.line + 1
        raise InputError("not valid JSON/YAML", path=p, line=line) from None
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise InputError("a parameter file must hold a mapping of sections", path=p)
    return data
