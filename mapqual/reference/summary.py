"""The summary.json page: RunSummary's JSON Schema, and each field's meaning from the code."""

from __future__ import annotations

import enum
import inspect
import json
import typing

from pydantic import BaseModel

from mapqual.reference.comments import cell, field_comments, prose, split_unit

_HEAD = """# `summary.json`

Each run's report folder holds `summary.json`, the JSON of one typed model,
`worker.report.summary.RunSummary`: the API (`GET /api/v1/schemas/summary` publishes the
same JSON Schema), the dashboard, the CLI (`mapqual runs show ID --json`) and the batch tables
all read it. Its `schema_version` is absent from files of version 1. This page is written from
the model each time the manual is built: first every part with its fields, then the JSON
Schema itself.
"""


def models() -> list[type[BaseModel]]:
    """RunSummary and every model nested in it, depth first, each once."""
    from worker.report.summary import RunSummary

    seen: list[type[BaseModel]] = []

    def walk(model: type[BaseModel]) -> None:
        if model in seen:
            return
        seen.append(model)
        for info in model.model_fields.values():
            for inner in _models_in(info.annotation):
                walk(inner)

    walk(RunSummary)
    return seen


def _models_in(hint: object) -> list[type[BaseModel]]:
    if isinstance(hint, type) and issubclass(hint, BaseModel):
        return [hint]
    return [m for a in typing.get_args(hint) for m in _models_in(a)]


def _enums_in(hint: object) -> list[type[enum.Enum]]:
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return [hint]
    return [e for a in typing.get_args(hint) for e in _enums_in(a)]


def _table(model: type[BaseModel]) -> str:
    comments = field_comments(model)
    rows = ["| field | type | unit | meaning |", "| --- | --- | --- | --- |"]
    for name, info in model.model_fields.items():
        unit, meaning = split_unit(comments.get(name, "") or (info.description or ""))
        kind = str(info.annotation).replace("typing.", "").replace("NoneType", "None")
        for m in _models_in(info.annotation):
            kind = kind.replace(f"{m.__module__}.{m.__name__}", m.__name__)
        for e in _enums_in(info.annotation):  # a vocabulary of worker.status: its strings
            values = f"{e.__name__} ({', '.join(m.value for m in e)})"
            kind = kind.replace(f"<enum '{e.__name__}'>", values)
            kind = kind.replace(f"{e.__module__}.{e.__name__}", values)
        kind = kind.replace("<class '", "").replace("'>", "")
        rows.append(f"| `{info.alias or name}` | {cell(kind)} | {cell(unit)} | {cell(meaning)} |")
    return "\n".join(rows)


def summary_page() -> str:
    """The whole summary.json page."""
    from worker.report.summary import RunSummary

    parts = [_HEAD]
    for model in models():
        doc = prose(inspect.cleandoc(model.__doc__ or ""))
        parts.append(f"## {model.__name__}\n\n{doc}\n\n{_table(model)}\n")
    schema = json.dumps(RunSummary.model_json_schema(), indent=2)
    parts.append(f"## JSON Schema\n\n```json\n{schema}\n```\n")
    return "\n".join(parts)
