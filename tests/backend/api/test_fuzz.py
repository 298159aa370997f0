"""A property-based fuzz of the whole API from its own OpenAPI schema (schemathesis): thousands
of generated requests by three users and by nobody, none answered 5xx, and afterwards the
database and the runs folder hold nothing half-written."""

from __future__ import annotations

import io
import itertools
import os
import tempfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import schemathesis
from fastapi import FastAPI
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis.errors import Unsatisfiable
from PIL import Image
from schemathesis import GenerationMode
from sqlalchemy import select

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import Job, Run, User, World
from backend.db.session import session_scope
from backend.store import add_user
from mapqual.app import create_app
from tests.services import ensure_redis, scratch_database

# The issue asks for at least this many generated requests in CI.
REQUESTS_MIN = 5000
# Hypothesis examples per operation: operations with few possible inputs (no parameters, or
# enums only) run out early, the others make up the total. 150 sends about 6,300 requests in
# about 100 s (120 sent 5,043; 300 sent about 12,600 in 186 s, most of it Hypothesis drawing
# the cases, when the whole suite came near CI's 25 minutes).
EXAMPLES_PER_OPERATION = 150
CALLERS = ("alice", "bob", "admin", None)


@dataclass
class FuzzEnv:
    app: FastAPI
    url: str
    runs_dir: Path
    keys: dict[str, str]
    broker: object
    temp_before: set[str]
    sent: Counter = field(default_factory=Counter)
    statuses: Counter = field(default_factory=Counter)
    callers: itertools.cycle = field(default_factory=lambda: itertools.cycle(CALLERS))


def _png(w: int = 60, h: int = 40) -> bytes:
    img = np.full((h, w), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def _upload_temp_dirs() -> set[str]:
    return {p for p in os.listdir(tempfile.gettempdir()) if p.startswith("mapqual-upload-")}


@pytest.fixture(scope="module")
def fuzz_env(tmp_path_factory):
    """A real PostgreSQL database with alice, bob and an admin, each of alice and bob owning a
    world and a job, and a broker database of its own (no worker: runs stay queued)."""
    import redis

    redis_url = ensure_redis().rsplit("/", 1)[0] + "/12"
    broker = redis.Redis.from_url(redis_url)
    broker.flushdb()
    runs_dir = tmp_path_factory.mktemp("fuzz") / "runs"
    with scratch_database("mapqual_fuzz") as url:
        upgrade(url)
        with session_scope(url) as s:
            keys = {n: add_user(s, n, is_admin=(n == "admin"))[1] for n in CALLERS if n}
        settings_ = Settings(DATABASE_URL=url, REDIS_URL=redis_url, MAPQUAL_RUNS_DIR=str(runs_dir))
        app = create_app(settings_)
        env = FuzzEnv(app, url, runs_dir, keys, broker, _upload_temp_dirs())
        with TestClient(app) as client:
            for i, name in enumerate(("alice", "bob")):
                auth = {"Authorization": f"Bearer {keys[name]}"}
                r = client.post(
                    "/api/v1/worlds",
                    headers=auth,
                    params={"wait": 30},
                    files=[("file", (f"plan{i}.png", _png(60 + 10 * i), "image/png"))],
                    data={"resolution": "0.05"},
                )
                assert r.status_code == 201, r.text
                r = client.post(
                    "/api/v1/jobs",
                    headers=auth,
                    json={"world_id": r.json()["id"], "runs": 2, "slam": "odometry"},
                )
                assert r.status_code == 202, r.text
            yield env
        broker.flushdb()
        broker.close()


def _fuzz_operation(env: FuzzEnv, client: TestClient, operation, mode) -> list[str]:
    """Up to EXAMPLES_PER_OPERATION generated requests to one operation; the failures."""
    failures: list[str] = []

    @settings(
        max_examples=EXAMPLES_PER_OPERATION,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=list(HealthCheck),
    )
    @given(case=operation.as_strategy(mode))
    def one(case) -> None:
        caller = next(env.callers)
        headers = {} if caller is None else {"Authorization": f"Bearer {env.keys[caller]}"}
        where = f"{case.method} {case.formatted_path} as {caller} ({mode.value})"
        env.sent[f"{case.method} {case.path}"] += 1
        try:
            response = case.call(headers=headers, session=client)
        except Exception as exc:  # the app raised: what a server answers with a 500
            env.statuses[500] += 1
            failures.append(f"{where}: raised {type(exc).__name__}: {str(exc)[:300]}")
            return
        env.statuses[response.status_code] += 1
        if response.status_code >= 500:
            failures.append(f"{where}: {response.status_code} {response.text[:300]}")
        open_route = case.path in ("/healthz", "/readyz")
        if caller is None and not open_route and response.status_code < 400:
            failures.append(f"{where}: {response.status_code} without a key")

    try:
        one()
    except Unsatisfiable:
        # an operation with nothing to get wrong (no parameters, no body) has no negative case
        assert mode is GenerationMode.NEGATIVE, f"{operation.label}: no positive case"
    return failures


def test_no_generated_request_is_answered_5xx(fuzz_env):
    schema = schemathesis.openapi.from_asgi("/api/v1/openapi.json", fuzz_env.app)
    failures: list[str] = []
    with TestClient(fuzz_env.app, raise_server_exceptions=False) as client:
        for result in schema.get_all_operations():
            operation = result.ok()
            for mode in (GenerationMode.POSITIVE, GenerationMode.NEGATIVE):
                failures += _fuzz_operation(fuzz_env, client, operation, mode)
    sent = sum(fuzz_env.sent.values())
    print(f"\nfuzz: {sent} requests; by status {dict(sorted(fuzz_env.statuses.items()))}")
    for op, n in sorted(fuzz_env.sent.items()):
        print(f"  {n:5d}  {op}")
    assert not failures, "\n".join(failures[:20])
    assert sent >= REQUESTS_MIN


def _job_status_of(statuses: set[str], job_status: str) -> bool:
    """Whether a job's status follows its runs' as the store's rule says."""
    if job_status == "cancelled":
        return True
    if "running" in statuses or ("queued" in statuses and len(statuses) > 1):
        return job_status == "running"
    if statuses == {"queued"}:
        return job_status == "queued"
    return job_status == ("failed" if "failed" in statuses else "done")


def test_after_the_fuzz_nothing_is_half_written(fuzz_env):
    assert sum(fuzz_env.sent.values()) >= REQUESTS_MIN, "the fuzz above did not run"
    with session_scope(fuzz_env.url) as s:
        admin_id = s.scalars(select(User.id).where(User.name == "admin")).one()
        worlds = {w.id: w for w in s.scalars(select(World))}
        jobs = list(s.scalars(select(Job)))
        runs = list(s.scalars(select(Run)))
        for w in worlds.values():
            geometry = (w.resolution, w.width_px, w.height_px, w.start_pose, w.occupancy)
            if w.status == "ready":
                assert all(v is not None for v in geometry), f"world {w.id} ready, no geometry"
            elif w.status == "invalid":
                assert w.error and all(v is None for v in geometry), f"world {w.id}"
            else:
                assert w.status == "pending" and w.upload, f"world {w.id} {w.status}"
        for job in jobs:
            mine = [r for r in runs if r.job_id == job.id]
            assert mine, f"job {job.id} has no run"
            world = worlds[job.world_id]
            # nobody but an admin made a job on somebody else's world, and runs belong to
            # their job's owner
            assert world.status == "ready"
            assert world.owner_id == job.owner_id or job.owner_id == admin_id, f"job {job.id}"
            assert all(r.owner_id == job.owner_id and r.world_id == job.world_id for r in mine)
            assert _job_status_of({r.status for r in mine}, job.status), f"job {job.id}"
        # no worker ran: nothing finished, nothing written to the runs folder
        assert {r.status for r in runs} <= {"queued", "cancelled"}
        assert not fuzz_env.runs_dir.exists() or not any(fuzz_env.runs_dir.iterdir())
    assert _upload_temp_dirs() <= fuzz_env.temp_before, "upload temp folders left behind"


@pytest.mark.parametrize(
    "method,path,kw",
    [
        ("GET", "/api/v1/worlds/2147483648", {}),
        ("GET", "/api/v1/jobs/2147483648", {}),
        ("POST", "/api/v1/jobs/99999999999/cancel", {}),
        ("GET", "/api/v1/runs/2147483648/report.zip", {}),
        ("GET", "/api/v1/jobs", {"params": {"world_id": 2**31}}),
        ("GET", "/api/v1/jobs", {"params": {"offset": 2**63}}),
        ("POST", "/api/v1/jobs", {"json": {"world_id": 2**31, "runs": 1}}),
        ("POST", "/api/v1/jobs", {"json": {"world_id": 1, "seeds": [2**31]}}),
    ],
)
def test_numbers_past_the_databases_integers_are_refused_not_a_500(fuzz_env, method, path, kw):
    # what the fuzz found first: PostgreSQL's `integer` ends at 2^31 - 1, and a larger id,
    # offset or seed reached the database and failed the query
    with TestClient(fuzz_env.app, raise_server_exceptions=False) as client:
        auth = {"Authorization": f"Bearer {fuzz_env.keys['alice']}"}
        r = client.request(method, path, headers=auth, **kw)
    assert r.status_code == 422, r.text
