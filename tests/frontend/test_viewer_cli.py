"""`mapqual viewer` serves viser's page on its port, makes the key of viewer links in its
database on first start (none is configured), and stops cleanly on SIGTERM."""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
import urllib.request

from tests.frontend.conftest import free_port


def test_viewer_command_serves_and_stops(tmp_path, own_redis):
    port = free_port()
    env = dict(os.environ, DATABASE_URL=f"sqlite:///{tmp_path / 'v.db'}", REDIS_URL=own_redis.url)
    env.pop("MAPQUAL_SECRET_KEY", None)  # the key is then made in the database
    proc = subprocess.Popen(
        [sys.executable, "-m", "mapqual", "viewer", "--port", str(port)],
        env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline, page = time.monotonic() + 60, ""
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=2) as r:
                    page = r.read().decode()
                break
            except OSError:
                time.sleep(0.2)
        assert "<html" in page.lower() and "viser" in page.lower(), proc.stderr
    finally:
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert f"mapqual viewer on http://127.0.0.1:{port}/" in err
    with sqlite3.connect(tmp_path / "v.db") as db:
        rows = db.execute("SELECT name, length(value) FROM app_secrets").fetchall()
    assert rows == [("viewer_token_key", 64)]


def test_viewer_command_rejects_a_bad_port(tmp_path):
    r = subprocess.run(
        [sys.executable, "-m", "mapqual", "viewer", "--port", "0"],
        capture_output=True, text=True, cwd=tmp_path, timeout=60,
    )  # fmt: skip
    assert r.returncode == 2 and "--port" in r.stderr
