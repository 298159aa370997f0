"""External SLAM through the whole service: a job picks an administrator's program by name, a
real Celery worker runs it; a program that kills itself mid-run, or stalls, ends its run
done / failed / slam_failed, and the same single worker process goes on to the next run."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.core.config import Settings
from mapqual.app import create_app
from tests.backend.integration.test_queue import Service, two_rooms
from tests.worker.slam.external.helpers import example, fake


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    svc = Service(tmp_path_factory.mktemp("service_ext"))
    programs = {
        "example": example(),
        "killed": fake("sigkill", 25),
        "stalls": fake("stall", 15),
    }
    settings = Settings(
        DATABASE_URL=svc.db_url, REDIS_URL=svc.redis_url, MAPQUAL_EXTERNAL_SLAM=programs
    )
    svc.client = TestClient(create_app(settings))
    svc.client.headers["Authorization"] = f"Bearer {svc.key}"
    yield svc
    svc.stop()


def _submit(svc, world_id: int, program: str, **external) -> int:
    body = {
        "world_id": world_id, "seeds": [1], "slam": "external",
        "params": {"slam": {"external": {"name": program, **external}},
                   "explore": {"time_limit": 60.0}},
    }  # fmt: skip
    r = svc.client.post("/api/v1/jobs", json=body)
    assert r.status_code == 202, r.text
    return r.json()["runs"][0]["id"]


def _programs_left() -> list[str]:
    """Command lines of live processes running the test programs (none may be left)."""
    left = []
    for proc in Path("/proc").iterdir():
        if proc.name.isdigit():
            try:
                cmd = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode()
            except OSError:
                continue
            if "fake_program.py" in cmd or "dead_reckoning_slam.py" in cmd:
                left.append(cmd)
    return left


def test_failing_programs_end_their_runs_and_the_worker_goes_on(service):
    wid = service.world(two_rooms())
    killed = _submit(service, wid, "killed")
    stalls = _submit(service, wid, "stalls", step_timeout_s=2.0)
    good = _submit(service, wid, "example")
    t0 = time.monotonic()
    runs = {}
    for rid in (killed, stalls, good):  # one worker process, one run after the other
        runs[rid] = service.wait(f"/api/v1/runs/{rid}", lambda r: r["status"] == "done", 300)
    assert time.monotonic() - t0 < 300
    k, s, g = runs[killed], runs[stalls], runs[good]
    assert (k["outcome"], k["reason"]) == ("failed", "slam_failed")
    detail = k["summary"]["stop_detail"]
    want = (
        "external SLAM 'killed' failed at step 25 (t=2.50 s): the program was killed by "
        "signal 9 | stderr: fake program: mode sigkill at step 25"
    )
    assert detail == want
    assert (s["outcome"], s["reason"]) == ("failed", "slam_failed")
    stalled = "at step 15 (t=1.50 s): the program took too long to answer (time-out)"
    assert stalled in s["summary"]["stop_detail"]
    assert (g["outcome"], g["summary"]["stop"]) == ("completed", "no_frontier")
    assert g["summary"]["params"]["slam"]["external"]["command"] == example()
    assert _programs_left() == []
    assert service.worker.poll() is None  # the worker lives on
    assert os.path.exists(f"/proc/{service.worker.pid}")
