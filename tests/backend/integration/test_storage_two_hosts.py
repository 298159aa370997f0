"""Issue 50's proof: an API and a worker that share no disk (the worker writes into a tmpfs
of its own mount namespace, which the API's process cannot see; its scratch folder is
deleted too), one PostgreSQL, one Redis, and a real S3 HTTP endpoint (moto's server) reached
through the product's own client. Every artifact route answers 200 with the stored bytes,
the job page links nothing that fails, and a worker SIGKILLed during its upload leaves no
half report visible while the run still ends once."""

from __future__ import annotations

import io
import re
import shutil
import signal
import subprocess
import sys
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest
import redis
from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.db.models import Run
from backend.db.session import session_scope
from backend.store.lifecycle import history, history_faults
from mapqual.app import create_app
from tests.backend.integration.test_exactly_once import Service, _rooms_png, db_url  # noqa: F401
from tests.s3server import make_bucket, raw_client, s3_server, slow_proxy
from tests.services import ensure_redis

REDIS_DB = 10
PREFIX = "deploy"


def _unshare_works() -> bool:
    try:
        return subprocess.run(["unshare", "-m", "true"], capture_output=True).returncode == 0
    except FileNotFoundError:
        return False


class TwoHosts(Service):
    """Service's worker, but on a "host" of its own: a private tmpfs as its runs folder."""

    def __init__(self, tmp: Path, url: str, redis_url: str, s3env: dict[str, str]):
        super().__init__(tmp, url, redis_url)
        self.bucket = make_bucket(s3env)
        self.storage = f"s3://{self.bucket}/{PREFIX}"
        self.worker_dir = tmp / "worker-disk"
        self.worker_dir.mkdir()
        self.env.update(s3env, MAPQUAL_STORAGE=self.storage, MAPQUAL_RUNS_DIR=str(self.worker_dir))
        api_dir = tmp / "api-disk"
        settings = Settings(DATABASE_URL=url, REDIS_URL=redis_url, MAPQUAL_STORAGE=self.storage,
                            MAPQUAL_RUNS_DIR=str(api_dir))  # fmt: skip
        self.client = TestClient(create_app(settings), base_url="https://testserver",
                                 headers=dict(self.client.headers))  # fmt: skip
        self.s3 = raw_client(s3env)

    def start_worker(self, **env: str) -> subprocess.Popen:
        argv = [sys.executable, "-m", "mapqual", "worker", "--concurrency", "1"]
        if _unshare_works():  # its own mount namespace: a tmpfs over its runs folder
            script = 'mount -t tmpfs tmpfs "$MAPQUAL_RUNS_DIR" && exec "$@"'
            argv = ["unshare", "-m", "sh", "-c", script, "sh", *argv]
        proc = subprocess.Popen(argv, env={**self.env, **env}, stdout=self.log, stderr=self.log,
                                start_new_session=True)  # fmt: skip
        self.workers.append(proc)
        return proc

    def objects(self, prefix: str) -> dict[str, bytes]:
        pages = self.s3.get_paginator("list_objects_v2").paginate(Bucket=self.bucket, Prefix=prefix)
        keys = [o["Key"] for p in pages for o in p.get("Contents", [])]
        return {k: self.s3.get_object(Bucket=self.bucket, Key=k)["Body"].read() for k in keys}

    def attempt_keys(self, run_id: int) -> set[str]:
        pages = self.s3.get_paginator("list_objects_v2").paginate(
            Bucket=self.bucket, Prefix=f"{PREFIX}/runs/{run_id}/"
        )
        return {o["Key"].split("/")[3] for p in pages for o in p.get("Contents", [])}


@pytest.fixture(scope="module")
def s3env() -> Iterator[dict[str, str]]:
    with s3_server() as env:
        yield env


@pytest.fixture
def hosts(tmp_path, db_url, s3env) -> Iterator[TwoHosts]:  # noqa: F811
    svc = TwoHosts(tmp_path, db_url, ensure_redis().rsplit("/", 1)[0] + f"/{REDIS_DB}", s3env)
    yield svc
    svc.stop()
    redis.Redis.from_url(svc.redis_url).flushdb()


def _done(svc: TwoHosts, run_ids: list[int]) -> bool:
    runs = svc.runs(run_ids).values()
    assert all(r.status in ("queued", "running", "done") for r in runs), [r.error for r in runs]
    return all(r.status == "done" for r in runs)


def _check_artifacts(svc: TwoHosts, run: Run) -> None:
    """Every artifact route of the run: 200 and the bytes in the bucket."""
    c, rid = svc.client, run.id
    assert run.report_dir.startswith(f"s3://{svc.bucket}/{PREFIX}/runs/{rid}/")
    key = run.report_dir.removeprefix(f"s3://{svc.bucket}/")
    stored = svc.objects(key + "/")
    name = lambda n: f"{key}/{n}"  # noqa: E731
    r = c.get(f"/api/v1/runs/{rid}/report.zip")
    assert r.status_code == 200 and r.content == stored[name("report.zip")]
    with zipfile.ZipFile(io.BytesIO(r.content)) as zf:  # the zip holds the report's files
        for n in ("summary.json", "relations_B.txt", "gt.tum", "sim.log"):
            assert zf.read(f"run{rid}/{n}") == stored[name(n)]
    for kind in ("A", "B", "SM"):
        r = c.get(f"/api/v1/runs/{rid}/relations", params={"kind": kind})
        assert r.status_code == 200 and r.content == stored[name(f"relations_{kind}.txt")]
    for ext in ("png", "pgm", "yaml"):
        r = c.get(f"/api/v1/runs/{rid}/map.{ext}")
        assert r.status_code == 200 and r.content == stored[name(f"map.{ext}")]
    for plot in ("errors", "map_overlay", "trajectories"):
        r = c.get(f"/runs/{rid}/plot/{plot}.png")
        assert r.status_code == 200 and r.content[:8] == b"\x89PNG\r\n\x1a\n"
        if name(f"{plot}.png") in stored:
            assert r.content == stored[name(f"{plot}.png")]
    for fmt, file in (("rosbag1", f"run{rid}.bag"), ("rosbag2", f"run{rid}_rosbag2.zip")):
        r = c.get(f"/api/v1/runs/{rid}/bag", params={"format": fmt})
        assert r.status_code == 200, r.text
        assert r.content == svc.objects(name(f"export/{file}"))[name(f"export/{file}")]
    est = stored[name("est.tum")]  # the run's own estimate scores like the run itself
    r = c.post(f"/api/v1/runs/{rid}/estimates", files={"file": ("est.tum", est)},
               data={"name": "again"})  # fmt: skip
    assert r.status_code == 201, r.text
    b_own = run.summary["relations"]["B"]["translation"]["mean"]
    assert r.json()["b_mean_t"] == pytest.approx(b_own, rel=1e-3, abs=1e-4)
    assert name("estimates/again/summary.json") in svc.objects(name("estimates/"))


def test_api_serves_everything_a_worker_on_another_disk_stored(hosts):
    svc = hosts
    run_ids = svc.job(_rooms_png(2, 1), [1, 2], "rbpf", 15.0)
    svc.start_worker()
    svc.wait("both runs done", lambda: _done(svc, run_ids), 900)
    shutil.rmtree(svc.worker_dir, ignore_errors=True)  # and nothing of the worker's disk here
    assert not svc.worker_dir.exists()
    for run in svc.runs(run_ids).values():
        _check_artifacts(svc, run)
    assert svc.client.get("/readyz").json()["storage"] == "ok"
    # the job page: every link and image it shows answers 200 (signed in as a browser)
    key = svc.client.headers.pop("Authorization").removeprefix("Bearer ")
    r = svc.client.post("/login", data={"key": key, "next": "/"}, follow_redirects=False)
    assert r.status_code == 303
    with session_scope(svc.db_url) as s:
        job_id = s.get_one(Run, run_ids[0]).job_id
    page = svc.client.get(f"/jobs/{job_id}").text
    links = set(re.findall(r'(?:href|src)="(/[^"]+)"', page))
    assert any("report.zip" in u for u in links) and any("bag?" in u for u in links)
    for url in sorted(links):
        r = svc.client.get(url.replace("&amp;", "&"))
        assert r.status_code == 200, (url, r.status_code, r.text[:200])


def test_a_worker_killed_during_its_upload_leaves_no_half_report(hosts, s3env):
    svc = hosts
    (run_id,) = svc.job(_rooms_png(2, 1), [3], "rbpf", 15.0)
    moto_port = int(s3env["AWS_ENDPOINT_URL"].rsplit(":", 1)[1])
    with slow_proxy(moto_port, 32_000) as port:  # its upload takes seconds: killed midway
        first = svc.start_worker(AWS_ENDPOINT_URL=f"http://127.0.0.1:{port}")
        svc.wait("the first attempt's upload", lambda: svc.attempt_keys(run_id), 900)
        svc.signal_worker(first, signal.SIGKILL)
    (killed,) = svc.attempt_keys(run_id)
    half = svc.objects(f"{PREFIX}/runs/{run_id}/{killed}/")
    assert not {"report.zip", "sim.log"} <= {k.rsplit("/", 1)[1] for k in half}  # midway
    run = svc.runs([run_id])[run_id]
    assert run.status == "running" and run.report_dir is None  # nothing points at the upload
    r = svc.client.get(f"/api/v1/runs/{run_id}/report.zip")
    assert r.status_code == 404 and "no report" in r.text
    svc.start_worker()  # takes the run over once the lease runs out
    svc.wait("the run done by the second attempt", lambda: _done(svc, [run_id]), 900)
    run = svc.runs([run_id])[run_id]
    with session_scope(svc.db_url) as s:
        events = history(s, run_id)
        assert history_faults(events) == []
        assert [e.to_status for e in events].count("done") == 1
    assert run.attempt != killed
    # the killed attempt's objects are swept by the winner, just after its commit
    svc.wait("the killed upload swept", lambda: svc.attempt_keys(run_id) == {run.attempt}, 60)
    r = svc.client.get(f"/api/v1/runs/{run_id}/report.zip")
    assert r.status_code == 200
    with zipfile.ZipFile(io.BytesIO(r.content)) as zf:
        assert zf.testzip() is None and f"run{run_id}/summary.json" in zf.namelist()


def test_a_done_run_whose_storage_is_gone_answers_503_with_the_reason(hosts):
    svc = hosts
    (rid,) = svc.job(_rooms_png(1, 1), [4], "rbpf", 5.0)
    svc.start_worker()
    svc.wait("the run done", lambda: _done(svc, [rid]), 900)
    with session_scope(svc.db_url) as s:  # the done run's bucket is not there any more
        run = s.get_one(Run, rid)
        run.report_dir = run.report_dir.replace(svc.bucket, "gone-bucket")
    for url in (f"/api/v1/runs/{rid}/report.zip", f"/api/v1/runs/{rid}/relations",
                f"/api/v1/runs/{rid}/bag"):  # fmt: skip
        r = svc.client.get(url)
        assert r.status_code == 503 and "cannot be reached" in r.json()["detail"], url
    assert svc.client.get(f"/api/v1/runs/{rid}/map.png").status_code == 200  # from the database
    assert svc.client.get(f"/api/v1/runs/{rid}/trajectory").status_code == 200
