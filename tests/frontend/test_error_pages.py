"""Error answers by client: a browser gets an HTML page with the navigation, the API and other
clients keep FastAPI's JSON; and the jobs list says what a finished job came to (outcomes by
kind, the B error of its scored runs), not "done" alone."""

from __future__ import annotations

import re

import numpy as np
import pytest
from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user, create_job, mark_run_started, save_world, store_run_result
from mapqual.app import create_app
from tests.frontend.test_pages import rooms
from tests.services import ensure_redis
from tests.summaries import make_summary, relation
from tests.summaries import stats as rel_stats
from worker.world.world import World

HTML = {"Accept": "text/html,application/xhtml+xml,*/*;q=0.8"}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    url = f"sqlite:///{tmp_path_factory.mktemp('errors') / 'errors.db'}"
    upgrade(url)
    with session_scope(url) as s:
        a, key = add_user(s, "a")
        w = save_world(s, owner_id=a.id, world=World.from_array(rooms(), 0.05, name="rooms"),
                       sha256="rooms", source_format="image")  # fmt: skip
        job = create_job(s, owner_id=a.id, world_id=w.id, slam="rbpf", params={}, seeds=[1, 2])
        for run, (reason, err) in zip(job.runs, [("time_limit", 0.123), ("collision", None)],
                                      strict=True):  # fmt: skip
            rels = {} if err is None else {"B": relation(rel_stats(err, 0.05, 200),
                                                         rel_stats(0.01, 0.005, 200))}  # fmt: skip
            summary = make_summary(outcome="failed", reason=reason, stop=reason, relations=rels)
            mark_run_started(s, run.id)
            store_run_result(
                s, run.id, summary=summary, t=np.arange(3.0), pose_gt=np.zeros((3, 3)),
                pose_est=np.zeros((3, 3)), map_ros=np.zeros((4, 4), np.int8),
                map_resolution=0.05, map_origin=(0.0, 0.0), report_dir=None,
            )  # fmt: skip
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/15"
    c = TestClient(create_app(Settings(DATABASE_URL=url, REDIS_URL=redis_url)),
                   base_url="https://testserver")  # fmt: skip
    c.headers["Authorization"] = f"Bearer {key}"
    return c


def test_a_browser_gets_an_html_error_page_with_the_navigation(client):
    r = client.get("/jobs/999", headers=HTML)
    assert r.status_code == 404 and r.headers["content-type"].startswith("text/html")
    assert "404 · Not found" in r.text and "no job with id 999" in r.text
    assert 'href="/explore"' in r.text and 'href="/worlds"' in r.text
    r = client.get("/no/such/page", headers=HTML)
    assert r.status_code == 404 and "<nav>" in r.text
    r = client.get("/explore?kind=bogus", headers=HTML)
    assert r.status_code == 400 and "unknown filter value(s): bogus" in r.text
    r = client.get("/jobs/notanumber", headers=HTML)
    assert r.status_code in (400, 404, 422) and "<nav>" in r.text


def test_the_api_and_other_clients_keep_json_errors(client):
    for path, headers in (("/api/v1/jobs/999", HTML), ("/jobs/999", {"Accept": "*/*"}),
                          ("/jobs/999", {"Accept": "application/json"})):  # fmt: skip
        r = client.get(path, headers=headers)
        assert r.status_code == 404 and r.headers["content-type"] == "application/json", path
        assert "detail" in r.json()


def test_the_jobs_list_shows_what_a_job_came_to(client):
    r = client.get("/", headers=HTML)
    assert r.status_code == 200
    row = re.search(r'<tr data-job="1".*?</tr>', r.text, re.S).group(0)
    cell = re.search(r'<td class="result([^"]*)">(.*?)</td>', row, re.S)
    text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", "", cell.group(2))).strip()
    # no run completed: flagged; the time-limited run is scored, the collision is not
    assert "none-completed" in cell.group(1)
    assert text == "1 time limit, 1 failed rbpf: B 0.123 m (mean of 1 scored run)"
    assert "7200 s (2 h)" in r.text  # the form says the default time limit and what it does
