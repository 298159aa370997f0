"""The manual's reference pages, written from the code itself (the MkDocs hook calls `pages`)."""

from __future__ import annotations

from collections.abc import Callable

from mapqual.reference.api import api_page
from mapqual.reference.cli import cli_page
from mapqual.reference.parameters import params_page
from mapqual.reference.settings import settings_page
from mapqual.reference.summary import summary_page

# page path in the manual (under docs/) -> the function that writes it
GENERATORS: dict[str, Callable[[], str]] = {
    "reference/cli.md": cli_page,
    "reference/api.md": api_page,
    "reference/summary.md": summary_page,
    "reference/parameters.md": params_page,
    "reference/settings.md": settings_page,
}


def pages() -> dict[str, str]:
    """Every generated page: its path under docs/ and its Markdown."""
    return {path: write() for path, write in GENERATORS.items()}
