"""The dashboard's job form offers the administrator's external programs by name
(external:NAME, from MAPQUAL_EXTERNAL_SLAM) and submits them through the API's handler."""

from __future__ import annotations

import os
import re
from html import unescape
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import Job
from backend.db.session import session_scope
from backend.store import add_user, save_world
from mapqual.app import create_app
from tests.frontend.test_pages import rooms
from tests.services import ensure_redis
from worker.world.world import World

PROGRAMS = {"deadreck": ["/usr/bin/python3", "/opt/slam/dead.py"], "mine": ["/opt/mine"]}


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    url = f"sqlite:///{tmp_path_factory.mktemp('form') / 'form.db'}"
    upgrade(url)
    with session_scope(url) as s:
        user, key = add_user(s, "a")
        w = save_world(s, owner_id=user.id, world=World.from_array(rooms(2, 1), 0.05, name="r"),
                       sha256="r", source_format="image")  # fmt: skip
        world_id = w.id
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/15"
    apps = {
        n: create_app(Settings(DATABASE_URL=url, REDIS_URL=redis_url, MAPQUAL_EXTERNAL_SLAM=p))
        for n, p in (("with", PROGRAMS), ("without", {}))
    }
    return {"apps": apps, "url": url, "key": key, "world": world_id}


def _signed_in(site, app="with") -> TestClient:
    client = TestClient(site["apps"][app], base_url="https://testserver")
    r = client.post("/login", data={"key": site["key"], "next": "/"}, follow_redirects=False)
    assert r.status_code == 303
    token = re.search(r'name="csrf_token" value="([^"]+)"', client.get("/").text).group(1)
    client.headers["X-CSRF-Token"] = token
    return client


def _choices(html: str) -> list[str]:
    form = html[html.index('<select name="slam"') :]
    return re.findall(r'<option value="([^"]+)"', form[: form.index("</select>")])


def test_the_form_lists_each_registered_program_and_no_bare_external(site):
    client = _signed_in(site)
    page = client.get("/").text
    assert _choices(page) == ["rbpf", "odometry", "oracle", "graph",
                              "external:deadreck", "external:mine"]  # fmt: skip
    assert ">external:mine (external program)</option>" in page
    shot = os.environ.get("MAPQUAL_FORM_HTML")  # for a look in a browser
    if shot:
        Path(shot).write_text(page.replace('"/static/', '"static/'))
    # no program registered: no external entry (it could only be refused)
    assert "external" not in " ".join(_choices(_signed_in(site, "without").get("/").text))


def test_picking_a_program_submits_a_job_with_its_command(site):
    client = _signed_in(site)
    form = {"world_id": str(site["world"]), "runs": "1", "slam": "external:mine"}
    r = client.post("/jobs", data=form, follow_redirects=False)
    assert r.status_code == 303, r.text
    job_id = int(r.headers["location"].rsplit("/", 1)[1])
    with session_scope(site["url"]) as s:
        job = s.get_one(Job, job_id)
        assert job.slam == "external:mine" and job.runs[0].slam == "external:mine"
        assert job.params["algorithm"] == "external"
        assert job.params["slam"]["external"]["command"] == PROGRAMS["mine"]
    assert "external:mine" in client.get("/").text.split("<h2>Jobs", 1)[1]  # the jobs table
    bad = client.post("/jobs", data={**form, "slam": "external:nope"})
    assert bad.status_code == 400
    refused = "slam.external.name 'nope' is not a registered program: 'deadreck', 'mine'"
    assert refused in unescape(bad.text)
    bare = client.post("/jobs", data={**form, "slam": "external"})
    assert bare.status_code == 400 and "give params.slam.external.name" in unescape(bare.text)
