"""Every URL of the running service that the README or the manual names answers (no 404, no
5xx), against a real server process: `uvicorn mapqual.app:app` on a database holding a real
run, serving the manual built in strict mode."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import httpx
import pytest

from tests.docs.conftest import ROOT
from tests.docs.tutorial_commands import environment, workspace
from tests.services import api_server, ensure_redis

pytestmark = pytest.mark.slow

# a path of the service, after a host of the README's examples or in backquotes / prose
_URL = re.compile(
    r"(?:(?:localhost|127\.0\.0\.1):8000|(?<=[\s`(]))"
    r"(/[^\s`'\"),<>]*)"
)
# the first segments of the service's paths (API, dashboard, manual, FastAPI's pages): other
# paths in the pages are files and ROS topics (/tf, /scan, /opt/...)
_SERVICE = {
    "api", "manual", "compare", "worlds", "jobs", "runs", "healthz", "readyz", "login",
    "logout", "static", "docs", "redoc", "openapi.json",
}  # fmt: skip
# what the pages write for an object, and the object of the test's database it stands for
_FILL = [
    (r"/runs/(\{id\}|\{run_id\}|ID)", "/runs/{run}"),
    (r"/jobs/(\{id\}|\{job_id\}|ID)", "/jobs/{job}"),
    (r"/worlds/(\{id\}|\{world_id\}|ID)", "/worlds/{world}"),
    (r"/datasets/(NAME|\{dataset\})", "/datasets/bormann"),
    (r"/worlds/(WORLD|\{name\})", "/worlds/office_a"),
    (r"/compare/\{kind\}", "/compare/paired"),
    (r"=N\b", "=64"),
    (r"=(\w+)\|\w+", r"=\1"),  # format=rosbag2|rosbag1: the first
]


def _pages() -> list[Path]:
    """The README and every hand-written page of the manual."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def named_urls() -> dict[str, str]:
    """URL path -> the page that names it first."""
    out: dict[str, str] = {}
    for page in _pages():
        for text in _URL.findall(page.read_text()):
            path = text.rstrip(".,;:")
            if path == "/api/v1":  # "the REST API under /api/v1": a prefix, not a page
                continue
            if path == "/" or path.split("/")[1].split("?")[0] in _SERVICE:
                out.setdefault(path, str(page.relative_to(ROOT)))
    return out


@pytest.fixture(scope="module")
def service(tmp_path_factory, built_site):
    """A real run stored by `mapqual run`, and the API serving it and the built manual."""
    work = workspace(tmp_path_factory.mktemp("service"))
    env = environment(work)
    subprocess.run(
        ["mapqual", "run", "worlds/bormann/office_a.yaml", "--time-limit", "10"],
        cwd=work, env=env, check=True, capture_output=True, timeout=600,
    )  # fmt: skip
    env.update(
        MAPQUAL_AUTH="off",
        MAPQUAL_MANUAL_DIR=str(built_site),
        REDIS_URL=ensure_redis().rsplit("/", 1)[0] + "/12",
    )
    with api_server(env, cwd=work) as (base, _):
        yield base


def test_the_pages_name_the_service_urls_users_need():
    urls = named_urls()
    for needed in ("/api/v1/docs", "/api/v1/openapi.json", "/manual/", "/compare"):
        assert needed in urls, f"no page names {needed}"
    assert len(urls) >= 20


def test_every_named_url_answers(service):
    ids = {"run": 1, "job": 1, "world": 1}  # the first of each in the test's database
    failures = []
    with httpx.Client(base_url=service, timeout=60) as client:
        for url, page in sorted(named_urls().items()):
            path = url
            for pattern, repl in _FILL:
                path = re.sub(pattern, repl, path)
            path = path.format(**ids)
            r = client.get(path)
            if r.status_code == 404 or r.status_code >= 500:
                failures.append(f"{url} ({page}) -> GET {path}: {r.status_code} {r.text[:120]}")
    assert not failures, "\n".join(failures)


def test_the_manual_is_served_and_the_dashboard_links_to_it(service):
    with httpx.Client(base_url=service, timeout=30) as client:
        r = client.get("/manual", follow_redirects=True)
        assert r.status_code == 200 and "mapqual manual" in r.text
        r = client.get("/manual/reference/cli/")
        assert r.status_code == 200 and "mapqual batch" in r.text
        assert client.get("/manual/../pyproject.toml").status_code == 404  # nothing outside
        dashboard = client.get("/").text
        assert 'href="/manual/"' in dashboard


def test_an_unbuilt_manual_still_answers(tmp_path):
    from starlette.testclient import TestClient

    from mapqual.app import create_app

    os.environ["MAPQUAL_MANUAL_DIR"] = str(tmp_path / "nothing")
    try:
        with TestClient(create_app()) as client:
            r = client.get("/manual/")
    finally:
        del os.environ["MAPQUAL_MANUAL_DIR"]
    assert r.status_code == 200 and "mkdocs build" in r.text
