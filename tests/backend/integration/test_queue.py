"""The service with its real parts: PostgreSQL, Redis, and a Celery worker process running
the real pipeline. Jobs go through the API, results come back in every format; a job is
cancelled mid-run; a worker is killed with SIGKILL mid-run and the run is redelivered."""

from __future__ import annotations

import io
import json
import os
import signal
import subprocess
import sys
import time
import uuid
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image
from sqlalchemy import create_engine, func, select, text

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import RunTrajectory
from backend.db.session import get_engine, session_scope
from backend.store import add_user, world_model
from mapqual.app import create_app
from tests.services import ensure_postgres, ensure_redis
from worker.pipeline import run_one
from worker.run_params import RunParams

VISIBILITY_S = 12
OFFICE_A = Path(__file__).parents[3] / "worlds/bormann/no_furniture/office_a.png"


def _png(img: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.where(img, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def two_rooms() -> bytes:
    occ = np.zeros((120, 200), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    occ[:, 100] = True
    occ[50:70, 100] = False
    return _png(occ)


def many_rooms(nx=5, ny=3, room_px=120) -> bytes:
    """nx x ny rooms of 6 m with 1 m doors: minutes of exploration."""
    h, w = ny * room_px + 1, nx * room_px + 1
    occ = np.zeros((h, w), bool)
    for i in range(nx + 1):
        occ[:, i * room_px] = True
    for j in range(ny + 1):
        occ[j * room_px, :] = True
    for i in range(1, nx):
        for j in range(ny):
            occ[j * room_px + 50 : j * room_px + 70, i * room_px] = False
    for j in range(1, ny):
        for i in range(nx):
            occ[j * room_px, i * room_px + 50 : i * room_px + 70] = False
    return _png(occ)


class Service:
    def __init__(self, tmp):
        admin_url = ensure_postgres()
        self.db_name = f"mapqual_it_{uuid.uuid4().hex[:10]}"
        self.admin = create_engine(admin_url, isolation_level="AUTOCOMMIT")
        with self.admin.connect() as c:
            c.execute(text(f'CREATE DATABASE "{self.db_name}"'))
        self.db_url = admin_url.rsplit("/", 1)[0] + f"/{self.db_name}"
        upgrade(self.db_url)
        self.redis_url = ensure_redis().rsplit("/", 1)[0] + "/14"
        import redis

        self.broker = redis.Redis.from_url(self.redis_url)
        self.broker.flushdb()
        self.env = dict(
            os.environ,
            DATABASE_URL=self.db_url,
            REDIS_URL=self.redis_url,
            MAPQUAL_RUNS_DIR=str(tmp / "runs"),
            MAPQUAL_VISIBILITY_TIMEOUT=str(VISIBILITY_S),
        )
        self.log = open(tmp / "worker.log", "ab")  # noqa: SIM115 - closed in stop()
        self.worker = None
        with session_scope(self.db_url) as s:
            self.key = add_user(s, "it")[1]
        settings = Settings(DATABASE_URL=self.db_url, REDIS_URL=self.redis_url)
        self.client = TestClient(create_app(settings))
        self.client.headers["Authorization"] = f"Bearer {self.key}"
        self.start_worker()

    def start_worker(self):
        self.worker = subprocess.Popen(
            [sys.executable, "-m", "mapqual", "worker", "--concurrency", "1"],
            env=self.env,
            stdout=self.log,
            stderr=self.log,
            start_new_session=True,
        )

    def kill_worker(self):
        os.killpg(self.worker.pid, signal.SIGKILL)  # the main process and its pool child
        self.worker.wait(timeout=10)

    def stop(self):
        if self.worker and self.worker.poll() is None:
            os.killpg(self.worker.pid, signal.SIGTERM)
            try:
                self.worker.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.kill_worker()
        self.log.close()
        self.broker.flushdb()
        get_engine(self.db_url).dispose()
        with self.admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{self.db_name}" WITH (FORCE)'))

    def world(self, png: bytes) -> int:
        r = self.client.post(
            "/api/v1/worlds",
            files={"file": ("w.png", png)},
            data={"resolution": "0.05"},
            params={"wait": 30},  # the analysis's outcome, not just the stored upload
        )
        assert r.status_code in (200, 201), r.text
        return r.json()["id"]

    def job(self, world_id, seeds, slam, time_limit):
        body = {
            "world_id": world_id,
            "seeds": seeds,
            "slam": slam,
            "params": {"explore": {"time_limit": time_limit}},
        }
        r = self.client.post("/api/v1/jobs", json=body)
        assert r.status_code == 202, r.text
        return r.json()

    def wait(self, path, done, timeout):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            doc = self.client.get(path).json()
            if done(doc):
                return doc
            time.sleep(0.3)
        raise AssertionError(f"timed out waiting on {path}: {doc}")


@pytest.fixture(scope="module")
def service(tmp_path_factory):
    svc = Service(tmp_path_factory.mktemp("service"))
    yield svc
    svc.stop()


def test_a_job_runs_to_done_and_every_result_format_is_served(service):
    wid = service.world(two_rooms())
    job = service.job(wid, [1, 2], "odometry", 120.0)
    job = service.wait(
        f"/api/v1/jobs/{job['id']}", lambda j: j["status"] in ("done", "failed"), 300
    )
    assert job["status"] == "done", job
    get = service.client.get
    for run in job["runs"]:
        rid = run["id"]
        doc = get(f"/api/v1/runs/{rid}").json()
        assert doc["status"] == "done" and doc["outcome"] in ("completed", "failed", "incomplete")
        assert doc["summary"]["seed"] == run["seed"] and "B" in doc["metrics"]["relations"]
        traj = get(f"/api/v1/runs/{rid}/trajectory", params={"kind": "gt", "format": "json"}).json()
        n = len(traj["t"])
        tum = get(f"/api/v1/runs/{rid}/trajectory", params={"kind": "gt", "format": "tum"}).text
        carmen = get(f"/api/v1/runs/{rid}/trajectory", params={"kind": "est", "format": "carmen"})
        assert len([ln for ln in tum.splitlines() if not ln.startswith("#")]) == n > 10
        assert carmen.text.startswith("FLASER 0 0.0 0.0 0.0 ")
        png = get(f"/api/v1/runs/{rid}/map.png")
        assert png.headers["content-type"] == "image/png" and png.content[:4] == b"\x89PNG"
        assert get(f"/api/v1/runs/{rid}/map.pgm").content[:2] == b"P5"
        assert "resolution:" in get(f"/api/v1/runs/{rid}/map.yaml").text
        for kind in ("A", "B"):
            rel = get(f"/api/v1/runs/{rid}/relations", params={"kind": kind})
            assert rel.status_code == 200 and len(rel.text.split("\n")[0].split()) == 8
        zf = zipfile.ZipFile(io.BytesIO(get(f"/api/v1/runs/{rid}/report.zip").content))
        names = {n.split("/", 1)[1] for n in zf.namelist()}
        assert {"summary.json", "sim.log", "map.pgm", "relations_B.txt"} <= names
        summary = json.loads(zf.read(f"run{rid}/summary.json"))
        assert summary["relations"] == doc["metrics"]["relations"]
    stats = get("/api/v1/stats").json()
    assert stats[0]["runs"] == 2


def test_cancel_stops_a_running_run_and_frees_the_worker(service):
    # A run of many wall-clock minutes: rbpf in a Bormann office with no time limit to speak
    # of (the oracle explores the test worlds in a couple of wall seconds, before a cancel
    # could reach it).
    big = service.job(service.world(OFFICE_A.read_bytes()), [1], "rbpf", 5000.0)
    rid = big["runs"][0]["id"]
    # generous: a worker on a cold numba cache compiles the SLAM kernels first
    running = service.wait(f"/api/v1/runs/{rid}", lambda r: r["progress"].get("t", 0) > 5, 300)
    assert running["status"] == "running", running["status"]
    assert service.client.post(f"/api/v1/jobs/{big['id']}/cancel").json()["status"] == "cancelled"
    # the single worker process is free again only if the long run really stopped
    small = service.job(service.world(two_rooms()), [9], "oracle", 60.0)
    t0 = time.monotonic()
    service.wait(f"/api/v1/jobs/{small['id']}", lambda j: j["status"] == "done", 120)
    assert time.monotonic() - t0 < 120
    run = service.client.get(f"/api/v1/runs/{rid}").json()
    assert run["status"] == "cancelled" and run["summary"] is None


def test_sigkill_mid_run_is_redelivered_and_stores_exactly_one_result(service):
    # rbpf (about 10x real time here), so that 150 simulated seconds last long enough in wall
    # time for the progress stored every 2 s to show the run mid-way
    job = service.job(service.world(many_rooms()), [5], "rbpf", 150.0)
    rid = job["runs"][0]["id"]
    mid = service.wait(f"/api/v1/runs/{rid}", lambda r: r["progress"].get("t", 0) > 20, 300)
    assert mid["status"] == "running", mid["status"]
    service.kill_worker()
    killed_at = time.time()
    assert service.client.get(f"/api/v1/runs/{rid}").json()["status"] == "running"
    service.start_worker()
    run = service.wait(f"/api/v1/runs/{rid}", lambda r: r["status"] == "done", VISIBILITY_S + 240)
    # Started over cleanly: the stored result is the one an uninterrupted run gives (runs are
    # deterministic for a seed), not a continuation of the killed one's state.
    with session_scope(service.db_url) as s:
        from backend.db.models import World

        world = world_model(s.get(World, job["world_id"]))
    fresh = run_one(world, RunParams.from_json(job["params"]), 5).summary.to_dict()
    assert run["summary"]["timings"]["sim_time_s"] == fresh["timings"]["sim_time_s"] > 20
    assert run["summary"]["relations"] == fresh["relations"]
    assert run["summary"]["outcome"] == fresh["outcome"]
    started = run["started_at"].replace("Z", "+00:00")
    from datetime import datetime

    assert datetime.fromisoformat(started).timestamp() > killed_at  # the run started over
    with session_scope(service.db_url) as s:
        n = s.scalar(
            select(func.count()).select_from(RunTrajectory).where(RunTrajectory.run_id == rid)
        )
    assert n == 2  # one gt and one est trajectory: exactly one stored result
