"""Exactly one result per run whatever the queue does, with real PostgreSQL, Redis and Celery
worker processes running the real pipeline: two workers executing the same run at once, a
worker SIGKILLed in the middle of each of 10 runs, and Redis restarted (without persistence)
while a job of 20 runs is queued and running.

Workers get a short lease and visibility timeout, so that a silent attempt is taken over and
an unacknowledged message comes back within seconds."""

from __future__ import annotations

import io
import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import redis
from fastapi.testclient import TestClient
from PIL import Image
from sqlalchemy import func, select

from backend.core.config import Settings
from backend.core.queue import EPOCH_KEY
from backend.db.migrate import upgrade
from backend.db.models import Run, RunEvent, RunTrajectory
from backend.db.session import get_engine, session_scope
from backend.store import add_user
from backend.store.lifecycle import history, history_faults
from mapqual.app import create_app
from tests.backend.plans import rooms_occupancy
from tests.services import ensure_redis, scratch_database

# apart from the batch (12), API (13, flushed by its fixtures), queue (14) and page (15) tests
REDIS_DB = 11
LEASE_S = 4
VISIBILITY_S = 6


def _rooms_png(nx: int, ny: int, room_px: int = 120) -> bytes:
    """nx x ny rooms of 6 m with 1 m doors, as an upload."""
    occ = rooms_occupancy(nx, ny, room_px)
    buf = io.BytesIO()
    Image.fromarray(np.where(occ, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


class Service:
    """A scratch database, a broker, the API in this process, and worker processes."""

    def __init__(self, tmp: Path, db_url: str, redis_url: str):
        self.tmp, self.db_url, self.redis_url = tmp, db_url, redis_url
        self.runs_dir = tmp / "runs"
        redis.Redis.from_url(redis_url).flushdb()
        self.env = dict(
            os.environ, DATABASE_URL=db_url, REDIS_URL=redis_url,
            MAPQUAL_RUNS_DIR=str(self.runs_dir), MAPQUAL_RUN_LEASE=str(LEASE_S),
            MAPQUAL_VISIBILITY_TIMEOUT=str(VISIBILITY_S),
        )  # fmt: skip
        self.workers: list[subprocess.Popen] = []
        self.log = open(tmp / "workers.log", "ab")  # noqa: SIM115 - closed in stop()
        with session_scope(db_url) as s:
            key = add_user(s, f"eo{uuid.uuid4().hex[:6]}")[1]
        settings = Settings(DATABASE_URL=db_url, REDIS_URL=redis_url)
        self.client = TestClient(create_app(settings))
        self.client.headers["Authorization"] = f"Bearer {key}"

    def start_worker(self) -> subprocess.Popen:
        proc = subprocess.Popen(
            [sys.executable, "-m", "mapqual", "worker", "--concurrency", "1"],
            env=self.env, stdout=self.log, stderr=self.log, start_new_session=True,
        )  # fmt: skip
        self.workers.append(proc)
        return proc

    def signal_worker(self, proc: subprocess.Popen, sig: int) -> None:
        os.killpg(proc.pid, sig)  # the main process and its pool child
        if sig == signal.SIGKILL:
            proc.wait(timeout=10)

    def stop(self) -> None:
        for proc in self.workers:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGCONT)
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=10)
        self.log.close()

    def job(self, png: bytes, seeds: list[int], slam: str, time_limit: float) -> list[int]:
        r = self.client.post(
            "/api/v1/worlds", files={"file": ("w.png", png)}, data={"resolution": "0.05"},
            params={"wait": 30},
        )  # fmt: skip
        assert r.status_code in (200, 201), r.text
        body = {"world_id": r.json()["id"], "seeds": seeds, "slam": slam,
                "params": {"explore": {"time_limit": time_limit}}}  # fmt: skip
        r = self.client.post("/api/v1/jobs", json=body)
        assert r.status_code == 202, r.text
        return [run["id"] for run in r.json()["runs"]]

    def runs(self, run_ids: list[int]) -> dict[int, Run]:
        with session_scope(self.db_url) as s:
            return {r.id: r for r in s.scalars(select(Run).where(Run.id.in_(run_ids)))}

    def wait(self, what: str, cond: Callable[[], object], timeout: float) -> object:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            found = cond()
            if found:
                return found
            time.sleep(0.1)
        raise AssertionError(f"timed out waiting for {what}; see {self.tmp / 'workers.log'}")

    def resent(self) -> int:
        """How many runs the workers' sweepers sent again (their log says so)."""
        self.log.flush()
        return (self.tmp / "workers.log").read_text(errors="replace").count("sent again")

    def folders(self) -> list[str]:
        return sorted(p.name for p in self.runs_dir.iterdir()) if self.runs_dir.exists() else []


def assert_each_stored_exactly_once(svc: Service, run_ids: list[int]) -> None:
    """Every run done, with one done event, one pair of trajectories, one folder, and a legal
    history; nothing an attempt left beside the run folders."""
    with session_scope(svc.db_url) as s:
        for run_id in run_ids:
            run = s.get_one(Run, run_id)
            events = history(s, run_id)
            assert run.status == "done", (run_id, run.status, run.error)
            assert history_faults(events) == [], (run_id, history_faults(events))
            assert [e.to_status for e in events].count("done") == 1
            assert events[-1].attempt == run.attempt  # the holder's result is the one kept
            n = s.scalar(select(func.count()).where(RunTrajectory.run_id == run_id))
            assert n == 2, (run_id, n)
            assert (svc.runs_dir / str(run_id) / "summary.json").exists()
    assert svc.folders() == sorted(str(i) for i in run_ids)


@pytest.fixture
def db_url() -> Iterator[str]:
    with scratch_database("mapqual_eo") as url:
        upgrade(url)
        yield url
        get_engine(url).dispose()


@pytest.fixture
def service(tmp_path, db_url) -> Iterator[Service]:
    svc = Service(tmp_path, db_url, ensure_redis().rsplit("/", 1)[0] + f"/{REDIS_DB}")
    yield svc
    svc.stop()
    redis.Redis.from_url(svc.redis_url).flushdb()


def _running(svc: Service, run_ids: list[int], skip: set[int] = frozenset()) -> Run | None:
    """A run mid-way, not among `skip`: running, with progress stored by its attempt (the
    first progress is stored as the pipeline starts, the next ones every 2 s)."""
    for run in svc.runs(run_ids).values():
        if run.id not in skip and run.status == "running" and "t" in run.progress:
            return run
    return None


def test_two_workers_on_the_same_run_store_one_result(service):
    svc = service
    (run_id,) = svc.job(_rooms_png(3, 2), [1], "rbpf", 120.0)
    first = svc.start_worker()
    holder = svc.wait("the first attempt mid-run", lambda: _running(svc, [run_id]), 120)
    svc.signal_worker(first, signal.SIGSTOP)  # alive but silent: no heartbeat
    svc.start_worker()  # gets the message again after the visibility timeout
    done = svc.wait(
        "the second attempt's result",
        lambda: svc.runs([run_id])[run_id].status == "done" and svc.runs([run_id])[run_id],
        180,
    )
    assert done.attempt != holder.attempt and done.attempts == 2
    first_dir = f"{run_id}.attempt-{holder.attempt}"
    svc.signal_worker(first, signal.SIGCONT)
    # the first attempt wakes up, finds at its next progress write that it lost, deletes its
    # folder and stores nothing
    svc.wait("the first attempt's folder gone", lambda: first_dir not in svc.folders(), 60)
    time.sleep(3)  # and whatever it still does afterwards changes nothing
    assert_each_stored_exactly_once(svc, [run_id])
    assert svc.resent() == 0  # the broker kept its queue: the sweepers sent nothing
    run = svc.runs([run_id])[run_id]
    assert (run.attempt, run.finished_at, run.summary) == (
        done.attempt, done.finished_at, done.summary
    )  # fmt: skip
    with session_scope(svc.db_url) as s:
        events = [(e.from_status, e.to_status, e.attempt) for e in history(s, run_id)]
    assert events == [
        ("queued", "running", holder.attempt),
        ("running", "running", done.attempt),
        ("running", "done", done.attempt),
    ]


def test_a_worker_killed_in_the_middle_of_each_of_10_runs(service):
    svc = service
    run_ids = svc.job(_rooms_png(5, 3), list(range(1, 11)), "odometry", 600.0)
    killed: dict[int, str] = {}  # run id -> the attempt that was killed
    worker = svc.start_worker()
    while len(killed) < len(run_ids):
        run = svc.wait("a run mid-way", lambda: _running(svc, run_ids, set(killed)), 120)
        svc.signal_worker(worker, signal.SIGKILL)
        killed[run.id] = run.attempt
        worker = svc.start_worker()
    svc.start_worker()  # a second one to finish sooner
    svc.wait(
        "all 10 runs done",
        lambda: all(r.status == "done" for r in svc.runs(run_ids).values()),
        240,
    )
    assert_each_stored_exactly_once(svc, run_ids)
    assert svc.resent() == 0
    for run_id, run in svc.runs(run_ids).items():
        assert run.attempts >= 2 and run.attempt != killed[run_id]


@pytest.fixture
def own_redis(tmp_path) -> Iterator[Callable[[], None]]:
    """A redis-server of our own on a free port, without persistence, and a way to restart it
    (the machine's Redis is never restarted)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    cmd = ["redis-server", "--port", str(port), "--bind", "127.0.0.1", "--save", "",
           "--appendonly", "no", "--dir", str(tmp_path)]  # fmt: skip
    procs = [subprocess.Popen(cmd, stdout=subprocess.DEVNULL)]
    client = redis.Redis(port=port)

    def up() -> None:
        for _ in range(100):
            try:
                client.ping()
                return
            except redis.ConnectionError:
                time.sleep(0.05)
        raise RuntimeError("redis-server did not start")

    def restart() -> None:
        procs[-1].terminate()
        procs[-1].wait(timeout=10)
        procs.append(subprocess.Popen(cmd, stdout=subprocess.DEVNULL))
        up()

    up()
    restart.url = f"redis://127.0.0.1:{port}/0"  # type: ignore[attr-defined]
    yield restart
    procs[-1].terminate()
    procs[-1].wait(timeout=10)


def test_a_redis_restart_loses_no_run_and_runs_none_twice(tmp_path, db_url, own_redis):
    svc = Service(tmp_path, db_url, own_redis.url)
    try:
        run_ids = svc.job(_rooms_png(3, 2), list(range(1, 21)), "odometry", 120.0)
        for _ in range(2):
            svc.start_worker()

        def mid_job() -> bool:
            states = [r.status for r in svc.runs(run_ids).values()]
            return states.count("done") >= 2 and states.count("queued") >= 10

        svc.wait("some runs done, most still queued", mid_job, 120)
        broker = redis.Redis.from_url(own_redis.url)
        epoch = broker.get(EPOCH_KEY)
        assert epoch is not None and broker.llen("mapqual") > 0
        own_redis()  # the queue and every unacknowledged message are gone
        # (workers and their sweepers reconnect at once and may write again meanwhile: the
        # proof that the data went is the epoch, which only a new broker lacks or makes anew)
        assert broker.get(EPOCH_KEY) != epoch
        svc.wait(
            "all 20 runs done",
            lambda: all(r.status == "done" for r in svc.runs(run_ids).values()),
            240,
        )
        assert_each_stored_exactly_once(svc, run_ids)
        with session_scope(db_url) as s:
            n_done = s.scalar(
                select(func.count()).select_from(RunEvent).where(RunEvent.to_status == "done")
            )
        assert n_done == 20
        assert svc.resent() > 0  # what the broker lost, the sweepers sent again
    finally:
        svc.stop()


def test_nothing_is_sent_again_while_the_broker_keeps_its_queue(service):
    from backend.services.sweeper import sweep

    svc = service
    run_ids = svc.job(_rooms_png(2, 1), [1, 2, 3], "odometry", 30.0)
    broker = redis.Redis.from_url(svc.redis_url)
    assert broker.llen("mapqual") == 3
    assert sweep(svc.db_url, svc.redis_url, LEASE_S) == []  # the same epoch: nothing lost
    assert broker.llen("mapqual") == 3
    broker.delete("mapqual", "mapqual:broker_epoch")  # what a restart without persistence does
    sent = [sweep(svc.db_url, svc.redis_url, LEASE_S) for _ in range(2)]
    assert sorted(sent[0]) == sorted(run_ids) and sent[1] == []  # each sent again once
    assert broker.llen("mapqual") == 3
