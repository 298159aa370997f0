"""The parameters page: every parameter dataclass, each field with its type, default, unit and
meaning (from the field's comment in the code)."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import typing
from pathlib import Path
from typing import Any

from mapqual.reference.comments import cell, code_cell, field_comments, prose, split_unit

_WORKER = Path(__file__).resolve().parents[2] / "worker"

_HEAD = """# Parameters

Every setting of a run, and of the tools around runs, as the code defines it: one frozen
dataclass per group, each field with its type, its default, its unit and what it means (the
field's comment in the source). This page is written from the code each time the manual is
built, so it is never behind it.

A run's parameters come from the defaults below, overridden by options of `mapqual run` /
`mapqual batch` or by `--params FILE` (YAML or JSON with the sections `sim`, `slam`, `explore`,
`eval`; nested groups as nested mappings, e.g. `slam: {graph: {link_gate_chi2: 20}}`), or by a
job's `params` over the API. Unknown keys, wrong types and bad values are refused in one line.
Every run stores the full set it used in its `summary.json`.
"""


def run_param_groups() -> list[tuple[str, type]]:
    """(key path, dataclass) of RunParams and every group nested in it, depth first."""
    from worker.run_params import RunParams

    out: list[tuple[str, type]] = []

    def walk(prefix: str, cls: type) -> None:
        out.append((prefix, cls))
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            inner = _dataclass_in(hints.get(f.name))
            if inner is not None:
                walk(f"{prefix}.{f.name}" if prefix else f.name, inner)

    walk("", RunParams)
    return out


def other_param_classes() -> list[type]:
    """Parameter dataclasses of worker/ outside a run's RunParams (found in the source: every
    `@dataclass` class named `...Params` or `...Spec`), sorted by module and name."""
    inside = {cls for _, cls in run_param_groups()}
    found: list[type] = []
    for path in sorted(_WORKER.rglob("*.py")):
        names = _dataclass_names(path)
        if not names:
            continue
        rel = path.relative_to(_WORKER.parent).with_suffix("")
        module = importlib.import_module(".".join(rel.parts))
        found += [getattr(module, n) for n in names if getattr(module, n) not in inside]
    return found


def _dataclass_names(path: Path) -> list[str]:
    """Names of the `@dataclass` classes of a file named like parameter sets."""
    tree = ast.parse(path.read_text())
    out = []
    for node in tree.body:
        if not isinstance(node, ast.ClassDef) or not node.name.endswith(("Params", "Spec")):
            continue
        for dec in node.decorator_list:
            target = dec.func if isinstance(dec, ast.Call) else dec
            name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
            if name == "dataclass":
                out.append(node.name)
    return out


def _dataclass_in(hint: Any) -> type | None:
    """The dataclass a field's type hint holds (itself or inside `X | None`), else None."""
    if dataclasses.is_dataclass(hint) and isinstance(hint, type):
        return hint
    inner = [a for a in typing.get_args(hint) if dataclasses.is_dataclass(a)]
    return inner[0] if len(inner) == 1 else None


def _type_name(hint: Any) -> str:
    if isinstance(hint, type):
        return hint.__name__
    return str(hint).replace("typing.", "").replace("NoneType", "None")


def _default(f: dataclasses.Field, hint: Any) -> str:
    if not f.init:
        return "(derived)"
    if f.default is not dataclasses.MISSING:
        value = f.default
    elif f.default_factory is not dataclasses.MISSING:
        inner = _dataclass_in(hint)
        if inner is not None:
            return f"see {inner.__name__}"
        value = f.default_factory()
    else:
        return "(required)"
    return code_cell(repr(value))


def class_table(cls: type, prefix: str = "") -> str:
    """A dataclass's fields as a Markdown table: key, type, default, unit, meaning."""
    hints = typing.get_type_hints(cls)
    comments = field_comments(cls)
    rows = ["| key | type | default | unit | meaning |", "| --- | --- | --- | --- | --- |"]
    for f in dataclasses.fields(cls):
        unit, meaning = split_unit(comments.get(f.name, ""))
        key = f"{prefix}.{f.name}" if prefix else f.name
        hint = hints.get(f.name)
        rows.append(
            f"| `{key}` | {cell(_type_name(hint))} | {_default(f, hint)} "
            f"| {cell(unit)} | {cell(meaning)} |"
        )
    return "\n".join(rows)


def _section(title: str, cls: type, prefix: str) -> str:
    doc = prose(inspect.cleandoc(cls.__doc__ or ""))
    where = f"`{cls.__module__}.{cls.__name__}`"
    return f"### {title}\n\n{where}. {doc}\n\n{class_table(cls, prefix)}\n"


def params_page() -> str:
    """The whole parameters page."""
    parts = [_HEAD, "## A run's parameters (`RunParams`)\n"]
    for prefix, cls in run_param_groups():
        title = f"`{prefix}`: {cls.__name__}" if prefix else f"top level: {cls.__name__}"
        parts.append(_section(title, cls, prefix))
    parts.append(
        "## Other parameter sets\n\nSettings of the tools around runs (the map score, exports, "
        "predictions, drivers of `mapqual simulate`, drifting problems from real logs), "
        "set by their commands' options or by Python.\n"
    )
    for cls in other_param_classes():
        parts.append(_section(cls.__name__, cls, ""))
    return "\n".join(parts)
