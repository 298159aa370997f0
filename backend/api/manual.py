"""The manual at /manual/: the MkDocs site built from docs/, or a page saying how to build it.

The site is static (`mkdocs build` writes it to site/ beside docs/); the API serves it as it
is, with no sign-in: it holds nothing but the manual. Where it has not been built, /manual/
still answers, with the two commands that build it, so the dashboard's link never ends in 404.
"""

from __future__ import annotations

import os
from pathlib import Path

from starlette.responses import HTMLResponse, RedirectResponse
from starlette.staticfiles import StaticFiles
from starlette.types import Receive, Scope, Send

MOUNT = "/manual"
# site/ of the checkout this package runs from (an editable install: the repository's root)
DEFAULT_SITE = Path(__file__).resolve().parents[1] / "site"

_NOT_BUILT = """<!doctype html><html lang="en"><head><meta charset="utf-8">
<title>mapqual manual</title><link rel="stylesheet" href="/static/style.css"></head>
<body><main><h1>The manual is not built on this server</h1>
<p>The manual's sources are the Markdown pages in <code>docs/</code> of the mapqual repository
(<code>docs/index.md</code> is its first page). To serve it here, build it in the checkout the
server runs from and reload this page:</p>
<pre>.venv/bin/pip install -e '.[dev]'
.venv/bin/mkdocs build</pre>
<p>or point <code>MAPQUAL_MANUAL_DIR</code> at a built site.
The REST API's own reference is at <a href="/api/v1/docs">/api/v1/docs</a>.</p>
</main></body></html>"""


def site_dir() -> Path:
    """The built site: MAPQUAL_MANUAL_DIR, else site/ beside the package."""
    return Path(os.environ.get("MAPQUAL_MANUAL_DIR") or DEFAULT_SITE)


class Manual:
    """ASGI app mounted at /manual: the built site's files, or the not-built page."""

    def __init__(self) -> None:
        self._static: StaticFiles | None = None
        self._dir: Path | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            return
        path, root = scope["path"], scope.get("root_path", "")
        if path == root or path == root.rstrip("/"):  # relative links need the trailing slash
            await RedirectResponse(f"{path}/", status_code=307)(scope, receive, send)
            return
        site = site_dir()
        if not (site / "index.html").is_file():
            await HTMLResponse(_NOT_BUILT)(scope, receive, send)
            return
        if self._static is None or self._dir != site:
            self._static, self._dir = StaticFiles(directory=site, html=True), site
        await self._static(scope, receive, send)
