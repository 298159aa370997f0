"""`mapqual viewer`: the live viewer (viser) of running and finished runs."""

from __future__ import annotations

import signal
import threading
from typing import Annotated

import typer

from mapqual.cli import app


@app.command("viewer")
def viewer(
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="Port to listen on.")] = 8080,
) -> None:
    """Watch runs in the browser: live while they run (over Redis), replayed once done.

    A run opens from the "open viewer" link on its job's dashboard page (MAPQUAL_VIEWER_URL
    says where browsers reach this server). The link carries a token signed for that run and
    its owner (MAPQUAL_SECRET_KEY, else a key kept in the database) that expires after
    MAPQUAL_VIEWER_TOKEN_TTL seconds; without a valid one the page shows no run at all.
    """
    from backend.core.config import get_settings
    from backend.db.migrate import upgrade
    from frontend.viewer import ViewerApp

    done = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: done.set())
    settings = get_settings()
    upgrade(settings.database_url)
    viewer_app = ViewerApp(
        settings.database_url, settings.redis_url, host, port, settings.secret_key
    )
    typer.echo(f"mapqual viewer on http://{host}:{viewer_app.port}/ (Ctrl+C stops it)", err=True)
    done.wait()
    viewer_app.stop()
