"""docker-compose.yml parses, every service's command is a valid mapqual invocation, and it
holds no secret and publishes nothing beyond the host's loopback.

No Docker engine runs here, so the services are checked the way the engine would start them:
each mapqual command line is parsed by the real CLI (click) without being executed, and the
${...} interpolations are resolved from .env.example as compose resolves them from .env.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest
import typer.main
import yaml

from mapqual.cli import app

ROOT = Path(__file__).resolve().parents[2]
COMPOSE_TEXT = (ROOT / "docker-compose.yml").read_text()
COMPOSE = yaml.safe_load(COMPOSE_TEXT)
# ${NAME}, ${NAME:?message}, ${NAME:-default}, ... (compose's interpolation)
INTERPOLATION = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)((?::?[-?+])[^}]*)?\}")


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
    assert set(COMPOSE["volumes"]) >= {"pgdata", "objects"}
    assert "ports" not in services["worker"]  # workers scale with --scale worker=N
    assert services["api"]["environment"]["DATABASE_URL"].startswith("postgresql+psycopg://")
    # the viewer reads the same database and Redis, and the dashboard links to its port
    assert (
        services["viewer"]["environment"]["REDIS_URL"]
        == services["worker"]["environment"]["REDIS_URL"]
    )
    assert services["viewer"]["ports"] == ["127.0.0.1:8080:8080"]
    assert services["api"]["environment"]["MAPQUAL_VIEWER_URL"].endswith(":8080")


@pytest.mark.parametrize("service", ["api", "worker", "viewer"])
def test_service_commands_are_valid_mapqual_invocations(service):
    argv = COMPOSE["services"][service]["command"]
    assert argv[0] == "mapqual"
    assert _parse_mapqual(argv[1:]) == argv[1]


def test_api_and_worker_share_no_disk_but_one_object_store():
    """Issue 50: workers may run on other machines, so no volume is mounted by both api and
    worker; both reach the same S3 bucket (the minio service) with the same settings."""
    services = COMPOSE["services"]
    mounts = {s: {v.split(":")[0] for v in services[s].get("volumes", [])} for s in services}
    assert not mounts["api"] & mounts["worker"]
    env = {s: services[s]["environment"] for s in ("api", "worker")}
    for key in ("MAPQUAL_STORAGE", "AWS_ENDPOINT_URL", "AWS_ACCESS_KEY_ID", "AWS_REGION"):
        assert env["api"][key] == env["worker"][key], key
    assert env["api"]["MAPQUAL_STORAGE"].startswith("s3://")
    assert env["api"]["AWS_ENDPOINT_URL"] == "http://minio:9000"
    assert "minio" in services and "healthcheck" in services["minio"]
    bucket = env["api"]["MAPQUAL_STORAGE"].removeprefix("s3://").split("/")[0]
    assert f"m/{bucket}" in " ".join(services["minio-bucket"]["entrypoint"])


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


def _env_example() -> dict[str, str]:
    """NAME=value lines of .env.example (comments and blank lines skipped)."""
    out = {}
    for line in (ROOT / ".env.example").read_text().splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            name, sep, value = line.partition("=")
            assert sep, f"not NAME=value: {line!r}"
            out[name.strip()] = value.strip()
    return out


def _strings(node, path=()):
    """Every (path, string) in the parsed compose file, keys included in the path."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _strings(v, (*path, str(k)))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _strings(v, (*path, str(i)))
    elif isinstance(node, str):
        yield path, node


def test_no_password_or_secret_is_written_in_the_compose_file():
    secretish = re.compile(r"PASSWORD|SECRET|TOKEN|_KEY$", re.I)
    checked = 0
    for path, value in _strings(COMPOSE):
        if secretish.search(path[-1]):
            # the whole value is one interpolation that must be set (${NAME:?...})
            m = INTERPOLATION.fullmatch(value)
            assert m and (m.group(2) or "").startswith(":?"), (path, value)
            checked += 1
        # credentials in a URL (scheme://user:password@host): the password is interpolated
        for url_pw in re.findall(r"://[^/:@\s]+:([^@\s]+)@", value):
            assert INTERPOLATION.fullmatch(url_pw), (path, value)
            checked += 1
    # POSTGRES_PASSWORD, the anchor's MAPQUAL_SECRET_KEY and DATABASE_URL's password at least
    assert checked >= 3
    postgres = COMPOSE["services"]["postgres"]["environment"]
    assert postgres["POSTGRES_PASSWORD"].startswith("${POSTGRES_PASSWORD:?")
    url = COMPOSE["services"]["api"]["environment"]["DATABASE_URL"]
    assert "${POSTGRES_PASSWORD:?" in url and "mapqual:mapqual@" not in url
    assert (
        "${MAPQUAL_SECRET_KEY:?"
        in COMPOSE["services"]["viewer"]["environment"]["MAPQUAL_SECRET_KEY"]
    )


def test_every_interpolated_variable_is_in_env_example_without_a_secret():
    used = {m.group(1) for m in INTERPOLATION.finditer(COMPOSE_TEXT)}
    assert {"POSTGRES_PASSWORD", "MAPQUAL_SECRET_KEY"} <= used
    example = _env_example()
    assert used <= set(example), used - set(example)
    # placeholders only: the secrets are left empty, so a copy not filled in fails loudly
    for name in used:
        assert example[name] == "", (name, example[name])
    # every service that runs mapqual reads .env (for the optional settings as well)
    for name in ("api", "worker", "viewer"):
        assert COMPOSE["services"][name]["env_file"] in (".env", [".env"]), name


def test_published_ports_are_on_the_loopback_only():
    published = 0
    for name, service in COMPOSE["services"].items():
        for port in service.get("ports", []):
            # "HOST_IP:HOST_PORT:CONTAINER_PORT"; without a host IP compose binds 0.0.0.0
            assert isinstance(port, str), (name, port)
            assert port.startswith("127.0.0.1:") and port.count(":") == 2, (name, port)
            published += 1
    assert published == 2  # the API and the viewer; nothing else is published at all


def test_env_file_is_git_ignored_and_the_example_is_not():
    def ignored(name: str) -> bool:
        r = subprocess.run(["git", "check-ignore", "-q", name], cwd=ROOT, check=False)
        assert r.returncode in (0, 1), f"git check-ignore failed on {name}"
        return r.returncode == 0

    assert ignored(".env") and not ignored(".env.example")
    # nor is it sent to the Docker build (where a `COPY . .` would bake it into the image)
    dockerignore = (ROOT / ".dockerignore").read_text().splitlines()
    assert ".env" in [ln.strip() for ln in dockerignore]
