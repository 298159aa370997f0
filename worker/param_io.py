"""Frozen parameter dataclasses to and from JSON/YAML through pydantic's TypeAdapter, strictly:
unknown keys, wrong types and bad values are errors that say which key and what was expected
(the API and the CLI show them as is)."""

from __future__ import annotations

import dataclasses
import json
from functools import cache
from pathlib import Path
from typing import Any, TypeVar, get_args, get_type_hints

import yaml
from pydantic import ConfigDict, TypeAdapter, ValidationError

from worker.errors import InputError

T = TypeVar("T")

# Strict: no str -> number or int -> bool coercion, no unknown keys, no nan/inf. Input is read
# in pydantic's JSON mode (lists for tuples, objects for dataclasses), as it is stored.
PARAMS_CONFIG = ConfigDict(strict=True, extra="forbid", allow_inf_nan=False)


def _configure(cls: type) -> None:
    """Give `cls` and every dataclass among its fields the strict config (the parameter modules
    stay free of pydantic; a class that sets its own `__pydantic_config__` keeps it)."""
    if "__pydantic_config__" not in cls.__dict__:
        cls.__pydantic_config__ = PARAMS_CONFIG  # type: ignore[attr-defined]
    for tp in get_type_hints(cls).values():
        for arg in (tp, *get_args(tp)):
            if dataclasses.is_dataclass(arg) and isinstance(arg, type):
                _configure(arg)


@cache
def adapter(cls: type[T]) -> TypeAdapter[T]:
    """The strict TypeAdapter of the parameter dataclass `cls` (built once)."""
    _configure(cls)
    return TypeAdapter(cls)


def to_dict(obj: Any) -> dict[str, Any]:
    """A parameter dataclass as plain JSON-serialisable data (tuples become lists); a field
    whose metadata says `omit_if_none` is left out while it is None."""
    return _omit_none(obj, adapter(type(obj)).dump_python(obj, mode="json"))


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
    a value outside a `Literal`'s choices, a non-finite number, or a value its class refuses.
    """
    if not isinstance(data, dict):
        raise InputError(f"{where or 'parameters'} must be a mapping, not {type(data).__name__}")
    try:
        text = json.dumps(data, allow_nan=True)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{where or 'parameters'}: not JSON data ({exc})") from None
    try:
        return adapter(cls).validate_json(text)
    except ValidationError as exc:
        raise InputError(_message(cls, exc.errors()[0], where)) from None


def _hint_at(cls: type, loc: tuple) -> Any:
    """The type hint reached from `cls` by the field names of `loc` (None where it stops)."""
    hint: Any = cls
    for name in loc:
        if not (isinstance(name, str) and dataclasses.is_dataclass(hint)):
            return None
        hint = _dataclass_of(get_type_hints(hint).get(name))
    return hint


def _dataclass_of(hint: Any) -> Any:
    """The dataclass inside an optional hint (`GraphSlamParams | None`), else the hint."""
    inner = [a for a in get_args(hint) if dataclasses.is_dataclass(a) and isinstance(a, type)]
    return inner[0] if len(inner) == 1 and type(None) in get_args(hint) else hint


def _message(cls: type, err: Any, where: str) -> str:
    """One line for pydantic's error `err`, in the words the CLI and the API have always used."""
    loc = tuple(err["loc"])
    key = ".".join([where] * bool(where) + [f"[{p}]" if isinstance(p, int) else p for p in loc])
    key = key.replace(".[", "[")
    kind, value = err["type"], err.get("input")
    if kind == "unexpected_keyword_argument":
        owner = _hint_at(cls, loc[:-1])
        valid = f" (valid: {', '.join(sorted(_fields(owner)))})" if owner is not None else ""
        return f"unknown parameter {key}{valid}"
    if kind == "value_error":  # __post_init__ refused the values
        error = err.get("ctx", {}).get("error")
        return f"{key or 'parameters'}: {error if error is not None else err['msg']}"
    if kind == "literal_error":
        choices = get_args(_hint_at(cls, loc)) or (err["ctx"]["expected"],)
        return f"{key} must be one of {', '.join(map(repr, choices))}, not {value!r}"
    if kind in ("missing", "too_long") and loc:
        tuple_loc = loc[:-1] if kind == "missing" else loc
        n = len(get_args(_hint_at(cls, tuple_loc)))
        tuple_key = key.rsplit("[", 1)[0] if kind == "missing" else key
        return f"{tuple_key} must have {n} elements"
    words = {
        "int_type": "must be an integer",
        "int_from_float": "must be an integer",
        "float_type": "must be a number",
        "finite_number": "must be a finite number",
        "bool_type": "must be true or false",
        "string_type": "must be a string",
        "dataclass_type": "must be a mapping",
        "tuple_type": "must be a list",
    }
    if kind in words:
        return f"{key} {words[kind]}, not {value!r}"
    return f"{key}: {err['msg']}"


def _fields(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls) if f.init]


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
