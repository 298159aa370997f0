"""`mapqual serve`, `mapqual worker` and `mapqual users add|list|revoke|rotate`: run and
administer the service."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Annotated

import typer

from mapqual.cli import app
from worker.errors import InputError

if TYPE_CHECKING:
    from sqlalchemy.orm import Session

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
    uvicorn.run("mapqual.app:app", host=host, port=port, workers=workers, log_level="info")


@app.command("worker")
def worker(
    concurrency: Annotated[int, typer.Option(min=1, help="Runs in parallel (processes).")] = 1,
    loglevel: Annotated[str, typer.Option(help="Celery log level.")] = "INFO",
) -> None:
    """A Celery worker that executes runs from the queue."""
    from backend.services.worker_host import install
    from worker.celery_conf import QUEUE
    from worker.slam.threads import claim_default

    celery_app = install()  # configured from the settings, its task served by the backend
    claim_default(concurrency)  # each process's share of the cores, inherited by the pool

    celery_app.worker_main(
        [
            "worker",
            f"--concurrency={concurrency}",
            f"--loglevel={loglevel}",
            "--pool=prefork",
            f"--queues={QUEUE}",
            "--without-gossip",
            "--without-mingle",
        ]
    )


@contextmanager
def _users() -> Iterator[Session]:
    """A transaction on the settings' (migrated) database; a refusal of the users service is
    bad input: one line, exit code 2."""
    from backend.services.database import transaction
    from backend.services.errors import ServiceError

    try:
        with transaction() as s:
            yield s
    except ServiceError as exc:
        raise InputError(exc.detail) from None


@users_app.command("add")
def users_add(
    name: Annotated[str, typer.Argument(help="The user's name (unique).")],
    admin: Annotated[bool, typer.Option("--admin", help="Sees every user's data.")] = False,
) -> None:
    """Create a user; the new API key is printed on the last line (shown only once)."""
    from backend.services import users

    with _users() as s:
        user, key = users.add(s, name, is_admin=admin)
    role = "admin" if user.is_admin else "user"
    typer.echo(f"created {role} {name!r}; API key (shown only once):", err=True)
    typer.echo(key)


@users_app.command("list")
def users_list() -> None:
    """Every user: name, admin, when revoked, when created (never a key)."""
    from backend.services import users

    with _users() as s:
        rows = [
            (u.name, "yes" if u.is_admin else "no",
             u.revoked_at.strftime("%Y-%m-%d %H:%M") if u.revoked_at else "no",
             u.created_at.strftime("%Y-%m-%d %H:%M"))
            for u in users.list_all(s)
        ]  # fmt: skip
    width = max([4, *(len(r[0]) for r in rows)])
    typer.echo(f"{'name':<{width}}  admin  {'revoked':<16}  created")
    for name, admin, revoked, created in rows:
        typer.echo(f"{name:<{width}}  {admin:<5}  {revoked:<16}  {created}")


@users_app.command("revoke")
def users_revoke(name: Annotated[str, typer.Argument(help="The user's name.")]) -> None:
    """Revoke a user: their dashboard sessions end at once, their API key within the API's
    key cache time (5 s); `users rotate` lets them back in with a new key."""
    from backend.services import users

    with _users() as s:
        users.revoke(s, name)
    typer.echo(f"revoked {name!r}: sessions ended, API key refused")


@users_app.command("rotate")
def users_rotate(name: Annotated[str, typer.Argument(help="The user's name.")]) -> None:
    """Give a user a new API key, printed on the last line (shown only once): the old key
    stops working (within the API's key cache time, 5 s), sessions end at once, and a revoked
    user is reinstated."""
    from backend.services import users

    with _users() as s:
        key = users.rotate(s, name)
    typer.echo(f"new API key of {name!r} (shown only once; the old one is dead):", err=True)
    typer.echo(key)
