"""MkDocs hook: adds the reference pages, written from the code at build time, to the manual.

The command line (the typer app), the REST API (the FastAPI app's OpenAPI document),
summary.json (RunSummary), every parameter dataclass and the service settings are read from
the code each build (`mapqual.reference`), so the manual cannot fall behind them.
"""

from __future__ import annotations

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files

from mapqual.reference import pages


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add each generated page (never written into docs/: it lives in the build only)."""
    for path, markdown in pages().items():
        files.append(File.generated(config, path, content=markdown))
    return files
