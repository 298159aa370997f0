"""`mapqual serve`, `mapqual worker` and `mapqual users add`: run and administer the service."""

from __future__ import annotations

from typing import Annotated

import typer

from mapqual.cli import app
from worker.errors import InputError

users_app = typer.Typer(
    rich_markup_mode=None, help="API users and their keys.", no_args_is_help=True
)
app.add_typer(users_app, name="users")


@app.command("serve")
def serve(
    host: Annotated[str, typer.Option(help="Address to listen on.")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="Port to listen on.")] = 8000,
    workers: Annotated[int, typer.Option(min=1, help="uvicorn worker processes.")] = 1,
    migrate: Annotated[bool, typer.Option(help="Apply database migrations first.")] = True,
) -> None:
    """The REST API (and dashboard) with uvicorn."""
    import uvicorn

    from backend.core.config import get_settings
    from backend.db.migrate import upgrade

    if migrate:
        upgrade(get_settings().database_url)
    uvicorn.run("backend.main:app", host=host, port=port, workers=workers, log_level="info")


@app.command("worker")
def worker(
    concurrency: Annotated[int, typer.Option(min=1, help="Runs in parallel (processes).")] = 1,
    loglevel: Annotated[str, typer.Option(help="Celery log level.")] = "INFO",
) -> None:
    """A Celery worker that executes runs from the queue."""
    from worker.celery_app import app as celery_app

    celery_app.worker_main(
        [
            "worker",
            f"--concurrency={concurrency}",
            f"--loglevel={loglevel}",
            "--pool=prefork",
            "--queues=mapqual",
            "--without-gossip",
            "--without-mingle",
        ]
    )


@users_app.command("add")
def users_add(
    name: Annotated[str, typer.Argument(help="The user's name (unique).")],
    admin: Annotated[bool, typer.Option("--admin", help="Sees every user's data.")] = False,
) -> None:
    """Create a user; the new API key is printed on the last line (shown only once)."""
    from backend.core.config import get_settings
    from backend.db.migrate import upgrade
    from backend.db.session import session_scope
    from backend.store import LOCAL_USER, add_user

    if name == LOCAL_USER:
        raise InputError(f"the name {LOCAL_USER!r} is reserved for embedded use")
    url = get_settings().database_url
    upgrade(url)
    try:
        with session_scope(url) as s:
            user, key = add_user(s, name, is_admin=admin)
            role = "admin" if user.is_admin else "user"
    except ValueError as exc:
        raise InputError(str(exc)) from None
    typer.echo(f"created {role} {name!r}; API key (shown only once):", err=True)
    typer.echo(key)
