"""The dashboard's pages over a real database (and Redis as the queue): sign-in, forms that go
through the API's handlers, a finished run's page, access rules, and the compare table."""

from __future__ import annotations

import io
import re
import time

import numpy as np
import pytest
from fastapi.testclient import TestClient
from PIL import Image

from backend.core.config import Settings
from backend.core.viewer_tokens import signing_key, verify
from backend.db.migrate import upgrade
from backend.db.models import Job, Run
from backend.db.session import session_scope
from backend.store import add_user, create_job, mark_run_started, save_world, store_run_result
from frontend.viewer import run_link
from mapqual.app import create_app
from tests.services import ensure_redis
from worker.pipeline import run_one
from worker.report.folder import write_report
from worker.run_params import RunParams
from worker.world.world import World

VIEWER = "http://viewer.example:8080"


def _png(occ: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.where(occ, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


def _room() -> np.ndarray:
    occ = np.zeros((80, 120), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    return occ


def rooms(nx: int = 3, ny: int = 2, room_px: int = 120) -> np.ndarray:
    """nx x ny rooms of 6 m at 0.05 m/px with 1 m doors."""
    occ = np.zeros((ny * room_px + 1, nx * room_px + 1), bool)
    occ[:, ::room_px] = True
    occ[::room_px, :] = True
    for i in range(1, nx):
        for j in range(ny):
            occ[j * room_px + 50 : j * room_px + 70, i * room_px] = False
    for j in range(1, ny):
        for i in range(nx):
            occ[j * room_px, i * room_px + 50 : i * room_px + 70] = False
    return occ


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """An app on a fresh database with two users, and one finished run of user `a`."""
    url = f"sqlite:///{tmp_path_factory.mktemp('pages') / 'pages.db'}"
    upgrade(url)
    world = World.from_array(rooms(), 0.05, name="owner_a_plan")
    params = RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 60.0}})
    result = run_one(world, params, 4)
    ex = result.exploration
    report = write_report(result, tmp_path_factory.mktemp("report"))
    with session_scope(url) as s:
        a, key_a = add_user(s, "a")
        _, key_b = add_user(s, "b")
        w = save_world(s, owner_id=a.id, world=world, sha256="rooms", source_format="image")
        job = create_job(s, owner_id=a.id, world_id=w.id, slam="odometry", params={}, seeds=[4])
        run_id = job.runs[0].id
        mark_run_started(s, run_id)
        store_run_result(
            s, run_id, summary=result.summary, t=ex.t, pose_gt=ex.pose_gt, pose_est=ex.pose_est,
            map_ros=ex.final_map.to_ros(), map_resolution=ex.final_map.resolution,
            map_origin=ex.final_map.origin, report_dir=str(report),
        )  # fmt: skip
        job_id, a_id = job.id, a.id
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/15"
    settings = Settings(DATABASE_URL=url, REDIS_URL=redis_url, MAPQUAL_VIEWER_URL=VIEWER)
    app = create_app(settings)
    return {"app": app, "url": url, "a": key_a, "b": key_b, "job": job_id, "run": run_id,
            "summary": result.summary.to_dict(), "report": report, "a_id": a_id}  # fmt: skip


def _client(site) -> TestClient:
    # https: the session cookie is Secure, and the client (as a browser) sends it on https only
    return TestClient(site["app"], base_url="https://testserver")


def _signed_in(site, who="a") -> TestClient:
    """A client signed in through the form, sending the session's CSRF token as a header (the
    forms' own token field is tested in tests/backend/api/test_sessions.py)."""
    client = _client(site)
    r = client.post("/login", data={"key": site[who], "next": "/"}, follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/"
    token = re.search(r'name="csrf_token" value="([^"]+)"', client.get("/").text).group(1)
    client.headers["X-CSRF-Token"] = token
    return client


def test_sign_in_starts_a_session_in_a_cookie(site):
    client = _client(site)
    r = client.get("/compare", follow_redirects=False)
    assert r.status_code == 303 and r.headers["location"] == "/login?next=/compare"
    r = client.post("/login", data={"key": "mq_wrong", "next": "/compare"})
    assert r.status_code == 401 and "unknown API key" in r.text
    r = client.post("/login", data={"key": site["a"], "next": "/compare"}, follow_redirects=False)
    assert r.headers["location"] == "/compare" and "httponly" in r.headers["set-cookie"].lower()
    assert client.get("/compare").status_code == 200
    # an open redirect is refused
    r = client.post(
        "/login", data={"key": site["a"], "next": "//evil.example"}, follow_redirects=False
    )
    assert r.headers["location"] == "/"
    token = re.search(r'name="csrf_token" value="([^"]+)"', client.get("/").text).group(1)
    client.post("/logout", data={"csrf_token": token})
    assert client.get("/", follow_redirects=False).status_code == 303
    # an Authorization header works without the cookie, as for the API
    bare = _client(site)
    assert bare.get("/", headers={"Authorization": f"Bearer {site['b']}"}).status_code == 200


def test_a_sign_in_is_committed_before_its_redirect_is_sent(site):
    """The browser follows the 303 at once; the page it asks for must find the new session.
    At the moment the response starts, another connection must see the session's row (a
    transaction ended after the response, FastAPI's default for a dependency with `yield`,
    lost this race on a loaded machine: the redirected page sent the browser back to the
    sign-in form)."""
    import asyncio
    import sqlite3
    from concurrent.futures import ThreadPoolExecutor
    from urllib.parse import urlencode

    db = site["url"].removeprefix("sqlite:///")

    def sessions() -> int:
        with sqlite3.connect(db) as c:
            return c.execute("SELECT count(*) FROM web_sessions").fetchone()[0]

    body = urlencode({"key": site["b"], "next": "/"}).encode()
    scope = {
        "type": "http", "asgi": {"version": "3.0"}, "http_version": "1.1", "method": "POST",
        "scheme": "https", "path": "/login", "raw_path": b"/login", "root_path": "",
        "query_string": b"", "server": ("testserver", 443), "client": ("127.0.0.1", 5000),
        "headers": [(b"host", b"testserver"), (b"content-length", str(len(body)).encode()),
                    (b"content-type", b"application/x-www-form-urlencoded")],
    }  # fmt: skip
    seen: dict = {}
    before = sessions()

    async def receive():
        return {"type": "http.request", "body": body, "more_body": False}

    async def send(message):
        if message["type"] == "http.response.start":
            seen["status"] = message["status"]
            seen["sessions"] = sessions()

    # in a thread of its own: the browser tests' Playwright keeps an event loop running in
    # this one
    with ThreadPoolExecutor(1) as pool:
        pool.submit(asyncio.run, site["app"](scope, receive, send)).result()
    assert seen["status"] == 303
    assert seen["sessions"] == before + 1


def _wait_ready(client, world_id: int, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while client.get(f"/api/v1/worlds/{world_id}").json()["status"] == "pending":
        assert time.monotonic() < deadline, "the world's analysis did not finish"
        time.sleep(0.1)
    assert client.get(f"/api/v1/worlds/{world_id}").json()["status"] == "ready"


def test_upload_form_stores_a_world_and_reports_bad_input(site):
    client = _signed_in(site, "b")
    occ = _room()
    occ[40, 20:100] = True
    r = client.post("/worlds", files={"file": ("hall.png", _png(occ))}, data={"resolution": "0.05"})
    # stored at once, analysed in the background: redirected to the list, which says so and
    # reloads itself (a GET: nothing is sent twice) until the analysis is done
    assert r.status_code == 200 and r.history[0].status_code == 303, r.text
    listed = client.get("/api/v1/worlds").json()
    assert [w["name"] for w in listed] == ["hall"]
    wid = listed[0]["id"]
    assert r.url.path == "/worlds" and r.url.params["uploaded"] == str(wid)
    if client.get(f"/api/v1/worlds/{wid}").json()["status"] == "pending":  # pending then too
        assert f"stored as #{wid}; it is being analysed" in r.text
        assert 'name="mapqual-refresh"' in r.text and f'id="world-{wid}"' in r.text
    _wait_ready(client, wid)
    r = client.get(f"/worlds?uploaded={wid}")
    assert f"stored as #{wid}; it is ready" in r.text
    assert f'src="/api/v1/worlds/{wid}/image?max_px=480"' in r.text
    assert "<th>free area</th>" in r.text and "m²" in r.text
    assert 'name="mapqual-refresh"' not in r.text
    again = client.post(
        "/worlds", files={"file": ("hall.png", _png(occ))}, data={"resolution": "0.05"}
    )
    assert again.status_code == 200 and "already stored" in again.text
    bad = client.post(
        "/worlds", files={"file": ("x.png", b"not an image")}, data={"resolution": "0.05"}
    )
    assert bad.status_code == 400 and "x.png: not a readable image" in bad.text
    neg = client.post("/worlds", files={"file": ("y.png", _png(occ))}, data={"resolution": "-1"})
    assert neg.status_code == 400 and "positive number" in neg.text
    assert len(client.get("/api/v1/worlds").json()) == 1  # nothing half-stored


def test_submit_form_queues_a_job_through_the_api(site):
    client = _signed_in(site, "b")
    wid = client.get("/api/v1/worlds").json()[0]["id"]
    form = {"world_id": str(wid), "runs": "2", "slam": "odometry", "time_limit": "42"}
    r = client.post("/jobs", data=form, follow_redirects=False)
    assert r.status_code == 303
    job_id = int(r.headers["location"].rsplit("/", 1)[1])
    with session_scope(site["url"]) as s:
        job = s.get_one(Job, job_id)
        assert job.slam == "odometry" and job.params["explore"]["time_limit"] == 42.0
        assert [r.seed for r in job.runs] == [1, 2] and job.status == "queued"
    page = client.get(f"/jobs/{job_id}")
    assert page.status_code == 200 and page.text.count('data-status="queued"') == 2
    jobs = client.get("/")
    assert f'href="/jobs/{job_id}"' in jobs.text and 'name="mapqual-refresh"' in jobs.text
    bad = client.post("/jobs", data={**form, "runs": "0"})
    assert bad.status_code == 400 and "invalid job" in bad.text
    other = client.post("/jobs", data={**form, "world_id": "1"})  # user a's world
    assert other.status_code == 400 and "no world with id 1" in other.text


def test_job_page_shows_the_finished_run(site):
    client = _signed_in(site)
    page = client.get(f"/jobs/{site['job']}").text
    b = site["summary"]["relations"]["B"]
    assert f"{b['translation']['mean']:.3f} ± {b['translation']['std']:.3f}" in page
    assert f"{b['rotation']['mean']:.4f} ± {b['rotation']['std']:.4f}" in page
    # the 95 % half-width of each mean, on the page and in the API's run output
    assert f"mean ± {b['translation']['ci95']:.3f} (95 % CI)" in page
    assert f"mean ± {b['rotation']['ci95']:.4f} (95 % CI)" in page
    run = client.get(f"/api/v1/runs/{site['run']}").json()
    assert run["summary"]["relations"]["B"]["translation"]["ci95"] == b["translation"]["ci95"] > 0
    assert f"{100 * site['summary']['coverage']:.0f} %" in page
    # the viewer link carries a token for this run and its owner (see test_viewer_access)
    prefix = run_link(VIEWER, site["run"], "")
    assert prefix == f"{VIEWER}/?websocket=ws://viewer.example:8080/run/{site['run']}/"
    (token,) = re.findall(f'href="{re.escape(prefix)}([^"]+)"', page)[:1]
    key = signing_key(site["url"], site["app"].state.settings.secret_key)
    grant = verify(key, site["run"], token)
    assert grant.user_id == site["a_id"]
    assert 'name="mapqual-refresh"' not in page  # nothing runs: no refreshing
    srcs = re.findall(r'<img src="([^"]+)"', page)
    assert len(srcs) == 4  # map, trajectories, errors, map overlay (issue 17)
    # the map-versus-floorplan figures, as the summary has them
    m = site["summary"]["map_score"]
    assert f"{m['distance_m']:.3f} m" in page and f"{m['precision']:.3f}" in page
    assert m["walls"] == "density" and "map walls: end-point density ridge" in page
    for src in srcs:
        r = client.get(src)
        assert r.status_code == 200 and r.content[:4] == b"\x89PNG", src
    # without the report's images: the trajectories are drawn from the database, and the
    # errors plot (which needs the report's error files) is neither offered nor served
    (site["report"] / "trajectories.png").unlink()
    (site["report"] / "errors.png").unlink()
    (site["report"] / "map_overlay.png").unlink()
    page = client.get(f"/jobs/{site['job']}").text
    assert len(re.findall(r'<img src="([^"]+)"', page)) == 2
    r = client.get(f"/runs/{site['run']}/plot/trajectories.png")
    assert r.status_code == 200 and Image.open(io.BytesIO(r.content)).size[0] > 500
    assert client.get(f"/runs/{site['run']}/plot/errors.png").status_code == 404
    assert client.get(f"/runs/{site['run']}/plot/map_overlay.png").status_code == 404


def test_other_owners_pages_answer_404(site):
    client = _signed_in(site, "b")
    assert client.get(f"/jobs/{site['job']}").status_code == 404
    assert client.get(f"/runs/{site['run']}/plot/trajectories.png").status_code == 404
    assert "owner_a_plan" not in client.get("/worlds").text  # no heading says it


def test_compare_table_matches_the_stats(site):
    client = _signed_in(site)
    stats = client.get("/api/v1/stats").json()
    page = client.get("/compare").text
    row = stats[0]
    # the table counts the relations of completed runs only (as the errors)
    completed = site["summary"]["outcome"] == "completed"
    n = site["summary"]["relations"]["B"]["translation"]["n"] if completed else 0
    assert row["world"] == "owner_a_plan" and row["completed"] == int(completed)
    assert f"<td>{n}</td>" in page
    t = row["translation"]
    for k in ("mean", "std", "min", "max"):
        if completed:
            assert f'data-v="{t[k]}">{t[k]:.3f}</td>' in page
        else:
            assert t[k] is None
    for kind in ("translation", "rotation"):
        r = client.get(f"/compare/{kind}.png")
        assert r.status_code == 200 and r.content[:4] == b"\x89PNG"
    with session_scope(site["url"]) as s:
        assert s.get_one(Run, site["run"]).outcome == site["summary"]["outcome"]
