"""Real servers for integration tests: use the machine's, or start our own where none runs."""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

PG_HOST, PG_PORT = "127.0.0.1", 5432
# MAPQUAL_TEST_REDIS_PORT gives a suite its own Redis (started below when none answers there),
# so that two suites on one machine do not share databases 10-15 of the machine's server.
REDIS_HOST = "127.0.0.1"
REDIS_PORT = int(os.environ.get("MAPQUAL_TEST_REDIS_PORT", "6379"))


def _port_open(host: str, port: int) -> bool:
    try:
        with socket.create_connection((host, port), timeout=0.5):
            return True
    except OSError:
        return False


def _wait_port(host: str, port: int, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if _port_open(host, port):
            return True
        time.sleep(0.2)
    return False


def ensure_postgres() -> str:
    """The admin URL of a running PostgreSQL on 127.0.0.1:5432, starting the cluster if needed."""
    if not _port_open(PG_HOST, PG_PORT):
        versions = sorted(glob.glob("/etc/postgresql/*"))
        if not versions or shutil.which("pg_ctlcluster") is None:
            raise RuntimeError("PostgreSQL is not running on 127.0.0.1:5432 and cannot be started")
        version = versions[-1].rsplit("/", 1)[-1]
        subprocess.run(
            ["pg_ctlcluster", "--skip-systemctl-redirect", version, "main", "start"], check=False
        )
        if not _wait_port(PG_HOST, PG_PORT, 30):
            raise RuntimeError("PostgreSQL did not come up on 127.0.0.1:5432")
    return f"postgresql+psycopg://postgres@{PG_HOST}:{PG_PORT}/test"


@contextmanager
def scratch_database(prefix: str) -> Iterator[str]:
    """The URL of a new, empty PostgreSQL database, dropped (with its connections) afterwards."""
    from sqlalchemy import create_engine, text

    from backend.db.session import get_engine

    admin_url = ensure_postgres()
    name = f"{prefix}_{uuid.uuid4().hex[:12]}"
    admin = create_engine(admin_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    url = admin_url.rsplit("/", 1)[0] + f"/{name}"
    try:
        yield url
    finally:
        get_engine(url).dispose()
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()


def ensure_redis() -> str:
    """The URL of a running Redis on 127.0.0.1:REDIS_PORT, starting one if needed."""
    if not _port_open(REDIS_HOST, REDIS_PORT):
        if shutil.which("redis-server") is None:
            raise RuntimeError(f"no Redis on 127.0.0.1:{REDIS_PORT} and none can be started")
        subprocess.run(
            [
                "redis-server",
                "--daemonize",
                "yes",
                "--bind",
                "127.0.0.1",
                "--port",
                str(REDIS_PORT),
                "--save",
                "",
                "--appendonly",
                "no",
            ],
            check=False,
        )
        if not _wait_port(REDIS_HOST, REDIS_PORT, 15):
            raise RuntimeError(f"Redis did not come up on 127.0.0.1:{REDIS_PORT}")
    return f"redis://{REDIS_HOST}:{REDIS_PORT}/0"


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on (now)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def api_server(
    env: dict[str, str], cwd: str | os.PathLike | None = None, wait_s: float = 90.0
) -> Iterator[tuple[str, subprocess.Popen]]:
    """`uvicorn mapqual.app:app` on a free loopback port with `env`: (its base URL, the
    process), once /healthz answers; terminated (killed after 20 s) afterwards."""
    import httpx

    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "uvicorn", "mapqual.app:app", "--port", str(port)],
        cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )  # fmt: skip
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + wait_s
        while True:
            if proc.poll() is not None:
                raise RuntimeError(proc.stderr.read().decode(errors="replace"))
            try:
                if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError("the server did not come up")
            time.sleep(0.2)
        yield base, proc
    finally:
        proc.terminate()
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def apt_install(package: str, binary: str) -> str:
    """The path of `binary`, installing Debian's `package` with apt-get when it is missing
    (as root); raises RuntimeError with apt-get's output tail when that cannot be done."""
    found = shutil.which(binary)
    if found:
        return found
    if shutil.which("apt-get") is None or os.geteuid() != 0:
        raise RuntimeError(
            f"{binary} is missing: install Debian's package (apt-get install {package})"
        )
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    subprocess.run(["apt-get", "update", "-q"], env=env, check=False, capture_output=True)
    done = subprocess.run(
        ["apt-get", "install", "-y", "-q", package], env=env, capture_output=True, text=True
    )
    found = shutil.which(binary)
    if not found:
        raise RuntimeError(
            f"apt-get install {package} failed:\n{done.stdout[-2000:]}{done.stderr[-2000:]}"
        )
    return found
