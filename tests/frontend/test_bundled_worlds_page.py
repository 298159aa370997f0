"""The worlds page's bundled data sets (issue 18) on a real PostgreSQL database: both listed
with their counts and licences, a world added through the page's own form (CSRF token and
all), then offered by the jobs form and run by a job."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import Job, World
from backend.db.session import session_scope
from backend.store import add_user
from mapqual.app import create_app
from tests.services import ensure_redis, scratch_database

WORLDS = Path(__file__).resolve().parents[2] / "worlds"
FORM_TOKEN = re.compile(r'name="csrf_token" value="([^"]+)"')


@pytest.fixture(scope="module")
def site():
    with scratch_database("mapqual_bundled") as url:
        upgrade(url)
        with session_scope(url) as s:
            keys = {name: add_user(s, name)[1] for name in ("carol", "dave")}
        redis_url = ensure_redis().rsplit("/", 1)[0] + "/15"
        app = create_app(Settings(DATABASE_URL=url, REDIS_URL=redis_url))
        with TestClient(app, base_url="https://testserver") as client:
            yield {"client": client, "url": url, "keys": keys}


def _sign_in(site, who: str) -> TestClient:
    client = site["client"]
    client.cookies.clear()
    r = client.post("/login", data={"key": site["keys"][who], "next": "/worlds"})
    assert r.status_code == 200 and r.url.path == "/worlds"
    return client


def _section(page: str, dataset: str) -> str:
    start = page.index(f'id="dataset-{dataset}"')
    end = page.find("</details>", start)
    return page[start:end]


def test_the_page_lists_both_data_sets_with_their_counts_and_licences(site):
    client = _sign_in(site, "carol")
    page = client.get("/worlds").text
    assert "<h2>Bundled data sets</h2>" in page
    for name, licence in (("bormann", "/api/v1/datasets/bormann/licence"),
                          ("schools", "/api/v1/datasets/schools/licence")):  # fmt: skip
        stems = {p.stem for p in (WORLDS / name).glob("*.yaml")}  # not from the code tested
        section = _section(page, name)
        assert f"{len(stems)} worlds" in section and f'href="{licence}"' in section
        assert set(re.findall(r'data-world="([^"]+)"', section)) == stems
        assert section.count('loading="lazy"') == len(stems)
        assert section.count(">add to my worlds</button>") == len(stems)
    assert {len(list((WORLDS / n).glob("*.yaml"))) for n in ("bormann", "schools")} == {32, 31}
    assert "MIT" in _section(page, "schools") and "LGPL" in _section(page, "bormann")
    thumb = client.get("/api/v1/datasets/schools/worlds/Borchen4/image?max_px=240")
    assert thumb.status_code == 200 and thumb.content[:4] == b"\x89PNG"


def test_a_world_added_from_the_page_is_offered_by_the_jobs_form_and_runs(site):
    client = _sign_in(site, "carol")
    page = client.get("/worlds").text
    action = "/worlds/bundled/bormann/Freiburg52_scan"
    assert f'action="{action}"' in page
    token = FORM_TOKEN.search(page).group(1)
    assert client.post(action, data={}).status_code == 403  # the form's token is needed
    r = client.post(action, data={"csrf_token": token}, follow_redirects=False)
    assert r.status_code == 303 and "bundled=1" in r.headers["location"]
    page = client.get(r.headers["location"]).text
    notice = r"world &#39;Freiburg52_scan&#39; added to your worlds as #(\d+); it is ready"
    (wid,) = re.findall(notice, page)
    assert f'<a href="#world-{wid}">in your worlds as #{wid}</a>' in page
    assert f'id="world-{wid}"' in page  # among your worlds, with its facts
    again = client.post(action, data={"csrf_token": token})
    assert f"is already yours as #{wid}" in again.text
    jobs = client.get("/").text
    assert f'<option value="{wid}">#{wid} Freiburg52_scan</option>' in jobs
    token = FORM_TOKEN.search(jobs).group(1)
    form = {"csrf_token": token, "world_id": wid, "runs": "1", "slam": "odometry"}
    r = client.post("/jobs", data=form, follow_redirects=False)
    assert r.status_code == 303, r.text
    job_id = int(r.headers["location"].rsplit("/", 1)[1])
    with session_scope(site["url"]) as s:
        job = s.get_one(Job, job_id)
        assert job.world_id == int(wid) and [run.seed for run in job.runs] == [1]
        assert s.get_one(World, int(wid)).owner_id == job.owner_id


def test_another_user_sees_the_data_sets_but_not_the_import_and_bad_names_say_so(site):
    client = _sign_in(site, "dave")
    page = client.get("/worlds").text
    assert "in your worlds as" not in page and "No worlds yet" in page
    token = FORM_TOKEN.search(page).group(1)
    r = client.post("/worlds/bundled/bormann/..%2Fschools%2FBorchen4", data={"csrf_token": token})
    assert r.status_code == 404 and "no world &#39;../schools/Borchen4&#39;" in r.text
    r = client.post("/worlds/bundled/nope/x", data={"csrf_token": token})
    assert r.status_code == 404 and "no bundled data set &#39;nope&#39;" in r.text
    assert "No worlds yet" in client.get("/worlds").text
