"""Per-owner quotas over HTTP, on a real database and broker: each limit answers 429 with a
message naming it, its value and its setting; the refused request stores and queues nothing;
the limits come from the settings (their environment names); the forms show the message."""

from __future__ import annotations

import io
import threading
from concurrent.futures import ThreadPoolExecutor
from datetime import timedelta

import numpy as np
from fastapi.testclient import TestClient
from PIL import Image
from sqlalchemy import func, select, update

from backend.core.config import Settings
from backend.db.models import Job, Run, World, utcnow
from backend.db.session import session_scope
from backend.store import add_job_runs
from mapqual.app import create_app


def _client(api, **limits) -> TestClient:
    """An app on the fixture's database and broker with these settings (environment names)."""
    base = api.client.app.state.settings
    settings = Settings(DATABASE_URL=api.url, REDIS_URL=base.redis_url, **limits)
    return TestClient(create_app(settings))


def _auth(api, user="alice") -> dict[str, str]:
    return {"Authorization": f"Bearer {api.keys[user]}"}


def _png(seed: int) -> bytes:
    occ = np.zeros((60, 80), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    occ[30, 10 : 10 + seed] = True  # a different world per seed (content hash)
    buf = io.BytesIO()
    Image.fromarray(np.where(occ, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _upload(client, api, seed: int, user="alice"):
    files = {"file": (f"w{seed}.png", _png(seed), "image/png")}
    return client.post(
        "/api/v1/worlds", files=files, data={"resolution": "0.05"}, headers=_auth(api, user),
        params={"wait": 30},
    )  # fmt: skip


def _world(api, user="alice") -> int:
    r = _upload(api.client, api, 1, user)
    assert r.status_code < 300, r.text
    return r.json()["id"]


def _count(api, model) -> int:
    with session_scope(api.url) as s:
        return s.scalar(select(func.count()).select_from(model))


def _jobs(client, api, wid, runs, time_limit=None, user="alice"):
    body = {"world_id": wid, "runs": runs, "slam": "odometry"}
    if time_limit is not None:
        body["params"] = {"explore": {"time_limit": time_limit}}
    return client.post("/api/v1/jobs", json=body, headers=_auth(api, user))


def _refused(r, *needles: str) -> None:
    assert r.status_code == 429, r.text
    detail = r.json()["detail"]
    assert detail.startswith("quota exceeded: ") and "\n" not in detail
    for needle in needles:
        assert needle in detail, detail


def test_runs_queued_or_running_at_once(api):
    wid = _world(api)
    client = _client(api, MAPQUAL_QUOTA_ACTIVE_RUNS=3)
    assert _jobs(client, api, wid, 2, 60).status_code == 202
    r = _jobs(client, api, wid, 2, 60)
    _refused(r, "2 runs queued or running", "2 more", "limit of 3 runs",
             "quota_active_runs", "MAPQUAL_QUOTA_ACTIVE_RUNS")  # fmt: skip
    assert _count(api, Job) == 1 and _count(api, Run) == 2
    _refused(_jobs(client, api, wid, 4, 60, user="admin"), "0 runs")  # admins too, per owner
    assert _jobs(client, api, wid, 1, 60).status_code == 202  # up to the limit exactly
    with session_scope(api.url) as s:  # finished runs no longer count
        s.execute(update(Run).values(status="done"))
    assert _jobs(client, api, wid, 3, 60).status_code == 202
    # the same Idempotency-Key again returns the stored job, quota or not
    headers = {**_auth(api), "Idempotency-Key": "k1"}
    body = {"world_id": wid, "runs": 1, "params": {"explore": {"time_limit": 60}}}
    with session_scope(api.url) as s:
        s.execute(update(Run).values(status="done"))
    first = client.post("/api/v1/jobs", json=body, headers=headers)
    assert _jobs(client, api, wid, 2, 60).status_code == 202  # at the limit now
    again = client.post("/api/v1/jobs", json=body, headers=headers)
    assert again.status_code == 202 and again.json()["id"] == first.json()["id"]


def test_simulated_hours_asked_for(api):
    wid = _world(api)
    client = _client(api, MAPQUAL_QUOTA_SIM_HOURS=1.0)
    assert _jobs(client, api, wid, 1, 1800).status_code == 202  # 0.5 h
    r = _jobs(client, api, wid, 2, 1200)  # 0.67 h more: 1.17 h
    _refused(r, "2 runs asking for 0.666667 simulated hours", "0.5 h asked for",
             "limit of 1 h", "quota_sim_hours", "MAPQUAL_QUOTA_SIM_HOURS")  # fmt: skip
    _refused(_jobs(client, api, wid, 1), "2 simulated hours")  # the default limit: 7200 s
    assert _count(api, Job) == 1
    assert _jobs(client, api, wid, 1, 1800).status_code == 202  # 1 h exactly
    with session_scope(api.url) as s:  # summed from a column, copied from the parameters
        assert s.scalars(select(Run.time_limit_s)).all() == [1800.0, 1800.0]
        s.execute(update(Run).values(status="done"))
        job = s.get_one(Job, 1)
        add_job_runs(s, job.id, [7, 8])  # a batch grown by seeds: the same parameters
        assert [r.time_limit_s for r in job.runs] == [1800.0, 1800.0, 1800.0]
        s.execute(update(Run).where(Run.seed == 8).values(time_limit_s=None))
    # a run stored without it (before the column existed) counts as the default, 2 h
    _refused(_jobs(client, api, wid, 1, 1), "2.5 h asked for")


def test_worlds_stored(api):
    client = _client(api, MAPQUAL_QUOTA_WORLDS=2)
    assert _upload(client, api, 1).status_code < 300
    assert _upload(client, api, 2).status_code < 300
    r = _upload(client, api, 3)
    _refused(r, "2 worlds stored", "limit of 2", "quota_worlds", "MAPQUAL_QUOTA_WORLDS")
    assert _count(api, World) == 2
    assert _upload(client, api, 3, user="bob").status_code < 300  # per owner


def test_uploads_in_the_last_day(api):
    client = _client(api, MAPQUAL_QUOTA_UPLOADS_PER_DAY=2)
    assert _upload(client, api, 1).status_code < 300
    assert _upload(client, api, 2).status_code < 300
    r = _upload(client, api, 3)
    _refused(r, "2 worlds uploaded in the last 24 h", "limit of 2 per day",
             "quota_uploads_per_day", "MAPQUAL_QUOTA_UPLOADS_PER_DAY")  # fmt: skip
    assert _count(api, World) == 2
    with session_scope(api.url) as s:  # one upload a day old: room for one more
        first = s.scalars(select(World).order_by(World.id)).first()
        first.created_at = utcnow() - timedelta(hours=25)
    assert _upload(client, api, 3).status_code < 300
    _refused(_upload(client, api, 4), "quota_uploads_per_day")


def test_the_forms_show_the_quota_message(api):
    wid = _world(api)
    client = _client(api, MAPQUAL_QUOTA_ACTIVE_RUNS=1, MAPQUAL_QUOTA_WORLDS=1)
    form = {"world_id": str(wid), "runs": "2", "slam": "odometry", "time_limit": "60"}
    r = client.post("/jobs", data=form, headers=_auth(api))
    assert r.status_code == 429 and "quota exceeded: " in r.text and "quota_active_runs" in r.text
    files = {"file": ("w2.png", _png(2), "image/png")}
    r = client.post("/worlds", files=files, data={"resolution": "0.05"}, headers=_auth(api))
    assert r.status_code == 429 and "MAPQUAL_QUOTA_WORLDS" in r.text and 'role="alert"' in r.text
    assert _count(api, Job) == 0 and _count(api, World) == 1


def test_parallel_requests_of_one_owner_cannot_all_pass(api):
    wid = _world(api)
    limit, n = 4, 12
    settings = Settings(DATABASE_URL=api.url, REDIS_URL=api.client.app.state.settings.redis_url,
                        MAPQUAL_QUOTA_ACTIVE_RUNS=limit)  # fmt: skip
    server = create_app(settings)
    barrier = threading.Barrier(n)

    def submit(_):
        with TestClient(server) as client:
            barrier.wait()
            return _jobs(client, api, wid, 1, 60).status_code

    with ThreadPoolExecutor(n) as pool:
        codes = list(pool.map(submit, range(n)))
    assert sorted(codes) == [202] * limit + [429] * (n - limit)
    assert _count(api, Run) == limit
