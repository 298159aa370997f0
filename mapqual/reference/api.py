"""The REST API page: every route of the FastAPI app, from its own OpenAPI document."""

from __future__ import annotations

from typing import Any

from mapqual.reference.comments import cell, prose

_HEAD = """# REST API

Every route of the REST API, written from the FastAPI app's own OpenAPI document each time
the manual is built. A running server publishes the same document at `/api/v1/openapi.json`
and an interactive page at `/api/v1/docs`. Requests carry `Authorization: Bearer KEY` (a key
from `mapqual users add`) unless the server runs with `MAPQUAL_AUTH=off`; objects of another
owner answer 404 like missing ones; bad input answers 4xx with a `detail`.
"""

_METHODS = ("get", "post", "put", "patch", "delete")


def openapi() -> dict[str, Any]:
    """The app's OpenAPI document, as the server publishes it."""
    from mapqual.app import app

    return app.openapi()


def operations() -> list[tuple[str, str, dict[str, Any]]]:
    """(METHOD, path, operation) of every route of the document, in its order."""
    doc = openapi()
    return [
        (method.upper(), path, op)
        for path, item in doc["paths"].items()
        for method, op in item.items()
        if method in _METHODS
    ]


def _type(schema: dict[str, Any]) -> str:
    if "$ref" in schema:
        return schema["$ref"].rsplit("/", 1)[1]
    if "anyOf" in schema:
        return " or ".join(_type(s) for s in schema["anyOf"])
    if schema.get("type") == "array":
        return f"array of {_type(schema.get('items', {}))}"
    if "enum" in schema:
        return " / ".join(map(str, schema["enum"]))
    return str(schema.get("type", "any"))


def _parameters(op: dict[str, Any]) -> str:
    rows = ["| parameter | in | type | required | meaning |", "| --- | --- | --- | --- | --- |"]
    for p in op.get("parameters", []):
        schema = p.get("schema", {})
        default = f" (default `{schema['default']!r}`)" if "default" in schema else ""
        meaning = p.get("description") or schema.get("description") or ""
        rows.append(
            f"| `{p['name']}` | {p['in']} | {cell(_type(schema))} | "
            f"{'yes' if p.get('required') else 'no'} | {cell(meaning + default)} |"
        )
    return "\n".join(rows) if len(rows) > 2 else ""


def _body(op: dict[str, Any]) -> str:
    content = op.get("requestBody", {}).get("content", {})
    if not content:
        return ""
    kinds = ", ".join(f"`{media}` ({_type(c.get('schema', {}))})" for media, c in content.items())
    return f"Body: {kinds}."


def _operation(method: str, path: str, op: dict[str, Any]) -> str:
    title = op.get("summary") or op.get("operationId", "")
    parts = [f"### `{method} {path}`\n", f"**{prose(title)}**\n"]
    if op.get("description"):
        parts.append(prose(op["description"].strip()) + "\n")
    for extra in (_parameters(op), _body(op)):
        if extra:
            parts.append(extra + "\n")
    codes = ", ".join(
        f"{code} {cell(r.get('description', ''))}" for code, r in op.get("responses", {}).items()
    )
    parts.append(f"Answers: {codes}.\n")
    return "\n".join(parts)


def _schemas(doc: dict[str, Any]) -> list[str]:
    """The bodies' and answers' schemas: each object's properties as a table."""
    parts = ["## Schemas\n", "The objects the routes above take and answer, by name.\n"]
    for name, schema in doc.get("components", {}).get("schemas", {}).items():
        parts.append(f"### {name}\n")
        if schema.get("description"):
            parts.append(prose(schema["description"].strip()) + "\n")
        props = schema.get("properties", {})
        if not props:
            parts.append(f"Type: {cell(_type(schema))}.\n")
            continue
        required = set(schema.get("required", []))
        rows = ["| field | type | required | meaning |", "| --- | --- | --- | --- |"]
        for prop, sub in props.items():
            default = f" (default `{sub['default']!r}`)" if "default" in sub else ""
            rows.append(
                f"| `{prop}` | {cell(_type(sub))} | {'yes' if prop in required else 'no'} "
                f"| {cell(sub.get('description', '') + default)} |"
            )
        parts.append("\n".join(rows) + "\n")
    return parts


def api_page() -> str:
    """The whole REST API page, routes grouped by their first path segment after the prefix."""
    parts = [_HEAD]
    group = None
    for method, path, op in operations():
        head = (op.get("tags") or [path.removeprefix("/api/v1").split("/")[1] or "root"])[0]
        if head != group:
            group = head
            parts.append(f"## {group}\n")
        parts.append(_operation(method, path, op))
    parts += _schemas(openapi())
    return "\n".join(parts)
