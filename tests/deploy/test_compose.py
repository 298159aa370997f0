"""docker-compose.yml parses, and every service's command is a valid mapqual invocation.

No Docker engine runs here, so the services are checked the way the engine would start them:
each mapqual command line is parsed by the real CLI (click) without being executed.
"""

from __future__ import annotations

from pathlib import Path

import pytest
import typer.main
import yaml

from mapqual.cli import app

ROOT = Path(__file__).resolve().parents[2]
COMPOSE = yaml.safe_load((ROOT / "docker-compose.yml").read_text())


# typer vendors click; its UsageError is the parent of every command-line error
UsageError = typer.BadParameter.__mro__[1]


def _parse_mapqual(argv: list[str]) -> str:
    """Resolve argv down to its leaf command and parse its options, as click would; returns
    the leaf command's name."""
    ctx = typer.main.get_command(app).make_context("mapqual", list(argv))
    while hasattr(ctx.command, "resolve_command"):  # a group: descend to the subcommand
        rest = [*getattr(ctx, "_protected_args", []), *ctx.args]
        name, sub, rest = ctx.command.resolve_command(ctx, rest)
        ctx = sub.make_context(name, rest, parent=ctx)
    return ctx.info_name


def test_compose_has_the_services_with_health_checks_and_volumes():
    services = COMPOSE["services"]
    assert {"redis", "postgres", "api", "worker", "viewer"} <= set(services)
    for name in ("redis", "postgres", "api", "viewer"):
        assert "healthcheck" in services[name], name
    assert set(COMPOSE["volumes"]) >= {"pgdata", "runs"}
    assert "ports" not in services["worker"]  # workers scale with --scale worker=N
    assert services["api"]["environment"]["DATABASE_URL"].startswith("postgresql+psycopg://")
    # the viewer reads the same database and Redis, and the dashboard links to its port
    assert (
        services["viewer"]["environment"]["REDIS_URL"]
        == services["worker"]["environment"]["REDIS_URL"]
    )
    assert services["viewer"]["ports"] == ["8080:8080"]
    assert services["api"]["environment"]["MAPQUAL_VIEWER_URL"].endswith(":8080")


@pytest.mark.parametrize("service", ["api", "worker", "viewer"])
def test_service_commands_are_valid_mapqual_invocations(service):
    argv = COMPOSE["services"][service]["command"]
    assert argv[0] == "mapqual"
    assert _parse_mapqual(argv[1:]) == argv[1]


def test_a_wrong_invocation_is_caught_by_the_same_check():
    with pytest.raises(UsageError):
        _parse_mapqual(["worker", "--concurrency", "many"])
    with pytest.raises(UsageError):
        _parse_mapqual(["serve", "--colour", "red"])


def test_dockerfile_default_command_is_valid():
    cmd = [ln for ln in (ROOT / "Dockerfile").read_text().splitlines() if ln.startswith("CMD")]
    argv = yaml.safe_load(cmd[0].removeprefix("CMD "))
    assert argv[0] == "mapqual"
    assert _parse_mapqual(argv[1:]) == "serve"
