"""Browser-test fixtures: the system Chromium (installed with apt-get when missing, never
skipped), the dashboard on a real uvicorn server, and the viewer, over the integration test's
real PostgreSQL, Redis and Celery worker."""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

from tests.services import apt_install
from tests.services import free_port as free_port  # the frontend tests import it from here

ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"
CHROMIUM_ARGS = ["--no-sandbox", "--use-gl=swiftshader", "--enable-unsafe-swiftshader"]


def chromium_path() -> str:
    """The system Chromium; installs Debian's `chromium` package when it is missing."""
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    try:
        return found or apt_install("chromium", "chromium")
    except RuntimeError as exc:
        pytest.fail(str(exc))
    if shutil.which("apt-get") is None or os.geteuid() != 0:
        pytest.fail("chromium is missing: install Debian's package (apt-get install chromium)")
    env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
    subprocess.run(["apt-get", "update", "-q"], env=env, check=False, capture_output=True)
    done = subprocess.run(
        ["apt-get", "install", "-y", "-q", "chromium"], env=env, capture_output=True, text=True
    )
    found = shutil.which("chromium")
    if not found:
        pytest.fail(f"apt-get install chromium failed:\n{done.stdout[-2000:]}{done.stderr[-2000:]}")
    return found


@pytest.fixture(scope="session")
def browser():
    from playwright.sync_api import sync_playwright

    path = chromium_path()
    with sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=path, args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture(scope="session")
def artifacts() -> Path:
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS


class Site:
    """The dashboard (uvicorn, in a thread) and the viewer over one service."""

    def __init__(self, service):
        import uvicorn

        from backend.core.config import Settings
        from frontend.viewer import ViewerApp
        from mapqual.app import create_app

        self.service = service
        viewer_port = free_port()
        self.viewer_url = f"http://127.0.0.1:{viewer_port}"
        settings = Settings(
            DATABASE_URL=service.db_url,
            REDIS_URL=service.redis_url,
            MAPQUAL_VIEWER_URL=self.viewer_url,
        )
        # the dashboard signs the viewer's links with the key the viewer checks (a developer's
        # .env may set MAPQUAL_SECRET_KEY)
        self.viewer = ViewerApp(
            service.db_url, service.redis_url, "127.0.0.1", viewer_port, settings.secret_key
        )
        port = free_port()
        self.url = f"http://127.0.0.1:{port}"
        config = uvicorn.Config(
            create_app(settings), host="127.0.0.1", port=port, log_level="warning"
        )
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 20
        while not self.server.started:
            if time.monotonic() > deadline:
                raise RuntimeError("the dashboard did not start")
            time.sleep(0.05)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)
        self.viewer.stop()


class OwnRedis:
    """A Redis server of our own on a free port: pub/sub channels are server-wide, and other
    test sessions on this machine use the shared server's channels and queues."""

    def __init__(self):
        self.port = free_port()
        self.proc = subprocess.Popen(
            ["redis-server", "--bind", "127.0.0.1", "--port", str(self.port), "--save", "",
             "--appendonly", "no"],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        self.url = f"redis://127.0.0.1:{self.port}/0"
        deadline = time.monotonic() + 10
        while True:
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.2).close()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise RuntimeError("redis-server did not start") from None
                time.sleep(0.05)

    def stop(self) -> None:
        self.proc.terminate()
        self.proc.wait(timeout=10)


def browser_service(tmp: Path, redis_url: str):
    """The integration test's Service (real PostgreSQL and Celery worker) on our own Redis."""
    import tests.backend.integration.test_queue as tq

    class BrowserService(tq.Service):
        def __init__(self):
            original = tq.ensure_redis
            tq.ensure_redis = lambda: redis_url  # Service appends its own db number
            try:
                super().__init__(tmp)
            finally:
                tq.ensure_redis = original

    return BrowserService()


@pytest.fixture(scope="session")
def own_redis() -> OwnRedis:
    """A Redis server of this test session only (see OwnRedis)."""
    if shutil.which("redis-server") is None:
        pytest.fail("redis-server is missing: install Debian's package (apt-get install redis)")
    own = OwnRedis()
    yield own
    own.stop()


@pytest.fixture(scope="module")
def site(tmp_path_factory, own_redis):
    service = browser_service(tmp_path_factory.mktemp("browser"), own_redis.url)
    s = Site(service)
    yield s
    s.stop()
    service.stop()
