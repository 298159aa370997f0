"""The service settings page: every environment variable of `backend.core.config.Settings`."""

from __future__ import annotations

from mapqual.reference.comments import cell, field_comments, split_unit

_HEAD = """# Service settings

The API, the workers and the viewer read their settings from the environment (or a `.env`
file in the working directory). Every variable, its default and its meaning, written from
`backend.core.config.Settings` each time the manual is built.
"""


def settings_page() -> str:
    """The whole settings page."""
    from backend.core.config import Settings

    comments = field_comments(Settings)
    rows = ["| variable | default | unit | meaning |", "| --- | --- | --- | --- |"]
    for name, info in Settings.model_fields.items():
        unit, meaning = split_unit(comments.get(name, ""))
        default = "" if info.is_required() else f"`{info.get_default(call_default_factory=True)!r}`"
        rows.append(
            f"| `{info.alias or name}` | {cell(default)} | {cell(unit)} | {cell(meaning)} |"
        )
    return _HEAD + "\n" + "\n".join(rows) + "\n"
