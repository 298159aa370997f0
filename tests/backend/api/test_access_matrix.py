"""Who may see what: every route of the OpenAPI schema (and every dashboard page), called by
the owner, by another user, by an admin and with no key, against objects of each owner, on a
real PostgreSQL database with finished runs that have reports."""

from __future__ import annotations

import io
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from fastapi.routing import APIRoute
from fastapi.testclient import TestClient
from PIL import Image

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import Job, Run
from backend.db.session import session_scope
from backend.store import add_user, create_job, save_world
from mapqual.app import create_app
from tests.backend.finished_runs import store_finished_run
from tests.services import ensure_redis, scratch_database
from worker.pipeline import run_one
from worker.report.folder import write_report
from worker.run_params import RunParams
from worker.world.world import World

OWNERS = ("alice", "bob")
CALLERS = ("alice", "bob", "admin", None)

# What each operation of the schema is, for the matrix. A route added to the API without a
# line here fails `test_the_matrix_covers_every_route_of_the_schema`.
OPEN, LIST, CREATE, OWNED = "open", "list", "create", "owned"
BUNDLED = "bundled"  # the bundled data sets: the same for every signed-in user
ROUTES: dict[tuple[str, str], str] = {
    ("GET", "/healthz"): OPEN,
    ("GET", "/readyz"): OPEN,
    ("POST", "/api/v1/worlds"): CREATE,
    ("GET", "/api/v1/worlds"): LIST,
    ("GET", "/api/v1/worlds/{world_id}"): OWNED,
    ("GET", "/api/v1/worlds/{world_id}/image"): OWNED,
    ("GET", "/api/v1/worlds/{world_id}/prediction"): OWNED,
    ("POST", "/api/v1/jobs"): CREATE,
    ("GET", "/api/v1/jobs"): LIST,
    ("GET", "/api/v1/jobs/{job_id}"): OWNED,
    ("POST", "/api/v1/jobs/{job_id}/cancel"): OWNED,
    ("GET", "/api/v1/runs/{run_id}"): OWNED,
    ("GET", "/api/v1/runs/{run_id}/trajectory"): OWNED,
    ("GET", "/api/v1/runs/{run_id}/map.{ext}"): OWNED,
    ("GET", "/api/v1/runs/{run_id}/relations"): OWNED,
    ("GET", "/api/v1/runs/{run_id}/report.zip"): OWNED,
    ("GET", "/api/v1/runs/{run_id}/bag"): OWNED,
    ("GET", "/api/v1/runs/{run_id}/estimates"): OWNED,
    # owner-only too: tests/backend/api/test_bags_estimates.py calls it as each caller
    ("POST", "/api/v1/runs/{run_id}/estimates"): OWNED,
    ("GET", "/api/v1/datasets"): BUNDLED,
    ("GET", "/api/v1/datasets/{dataset}/licence"): BUNDLED,
    ("GET", "/api/v1/datasets/{dataset}/worlds/{name}/image"): BUNDLED,
    # the import is the caller's world: test_an_imported_world_belongs_to_the_importer
    ("POST", "/api/v1/datasets/{dataset}/worlds/{name}/import"): CREATE,
    ("GET", "/api/v1/stats"): LIST,
    # public, like the OpenAPI document that holds it too: it describes the API, no one's data
    ("GET", "/api/v1/schemas/summary"): OPEN,
}
# Dashboard pages (not in the schema) that read one owner's object.
OWNED_PAGES = ("/jobs/{job_id}", "/runs/{run_id}/plot/trajectories.png")
LIST_PAGES = ("/", "/worlds", "/compare", "/compare/translation.png", "/explore",
              "/explore/runs.csv", "/explore/groups.csv", "/explore/plot/scores.png")  # fmt: skip


def _rooms() -> np.ndarray:
    occ = np.zeros((121, 241), bool)
    occ[:, ::120] = True
    occ[::120, :] = True
    occ[50:70, 120] = False
    return occ


def _png(occ: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(np.where(occ, 0, 255).astype(np.uint8)).save(buf, format="PNG")
    return buf.getvalue()


@dataclass
class Owned:
    """One owner's objects: a world, a finished job and run (with a report), a queued job."""

    world: int
    job: int
    run: int
    queued_job: int


@dataclass
class Site:
    client: TestClient
    url: str
    keys: dict[str, str]
    ids: dict[str, int]
    owned: dict[str, Owned]

    def call(self, method: str, path: str, caller: str | None, **kw):
        headers = {} if caller is None else {"Authorization": f"Bearer {self.keys[caller]}"}
        return self.client.request(method, path, headers=headers, follow_redirects=False, **kw)

    def new_queued_job(self, owner: str) -> int:
        with session_scope(self.url) as s:
            job = create_job(
                s, owner_id=self.ids[owner], world_id=self.owned[owner].world, slam="odometry",
                params={}, seeds=[1],
            )  # fmt: skip
            return job.id


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """alice and bob each own a world, a job with a finished run (report folder and all) and a
    queued job; an admin owns nothing."""
    world = World.from_array(_rooms(), 0.05, name="two_rooms")
    params = RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 30.0}})
    sim_log = tmp_path_factory.mktemp("sim") / "sim.log"
    result = run_one(world, params, 2, sim_log=sim_log)  # its sim.log: GET /runs/{id}/bag
    import redis

    # a broker database no other test uses (jobs submitted here are sent, never run)
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/10"
    redis.Redis.from_url(redis_url).flushdb()
    with scratch_database("mapqual_access") as url:
        upgrade(url)
        keys, ids, owned = {}, {}, {}
        with session_scope(url) as s:
            for name in ("alice", "bob", "admin"):
                user, keys[name] = add_user(s, name, is_admin=(name == "admin"))
                ids[name] = user.id
            for name in OWNERS:
                w = save_world(
                    s, owner_id=ids[name], world=world, sha256=f"plan-{name}",
                    source_format="image",
                )  # fmt: skip
                done = create_job(
                    s, owner_id=ids[name], world_id=w.id, slam="odometry",
                    params=params.to_json(), seeds=[2],
                )  # fmt: skip
                queued = create_job(
                    s, owner_id=ids[name], world_id=w.id, slam="odometry", params={}, seeds=[1]
                )
                owned[name] = Owned(w.id, done.id, done.runs[0].id, queued.id)
        for name in OWNERS:
            report = write_report(result, tmp_path_factory.mktemp(f"report-{name}"))
            (Path(report) / "sim.log").write_bytes(sim_log.read_bytes())
            store_finished_run(url, owned[name].run, result, Path(report))
        settings = Settings(DATABASE_URL=url, REDIS_URL=redis_url)
        with TestClient(create_app(settings)) as client:
            yield Site(client, url, keys, ids, owned)
        redis.Redis.from_url(redis_url).flushdb()


def _fill(path: str, objects: Owned) -> str:
    return path.format(world_id=objects.world, job_id=objects.job, run_id=objects.run, ext="png")


def _routes(routes) -> list[APIRoute]:
    """Every APIRoute of an app, inside included routers too."""
    out = []
    for r in routes:
        if isinstance(r, APIRoute):
            out.append(r)
        elif hasattr(r, "original_router"):  # FastAPI's record of an included router
            out += _routes(r.original_router.routes)
    return out


def test_the_matrix_covers_every_route_of_the_schema(site):
    schema = site.client.get("/api/v1/openapi.json").json()
    ops = {(m.upper(), p) for p, item in schema["paths"].items() for m in item}
    assert ops == set(ROUTES), f"routes without a matrix line: {ops - set(ROUTES)}"
    pages = {(m, r.path) for r in _routes(site.client.app.routes) if not r.include_in_schema
             for m in r.methods}  # fmt: skip
    known = {
        ("GET", "/login"), ("POST", "/login"), ("POST", "/logout"), ("GET", "/"),
        ("POST", "/jobs"), ("GET", "/jobs/{job_id}"), ("GET", "/runs/{run_id}/plot/{name}.png"),
        ("GET", "/worlds"), ("POST", "/worlds"), ("GET", "/compare"),
        ("GET", "/compare/{kind}.png"), ("POST", "/worlds/bundled/{dataset}/{name:path}"),
        ("GET", "/explore"), ("GET", "/explore/runs.csv"), ("GET", "/explore/groups.csv"),
        ("GET", "/explore/plot/{name}.png"),
    }  # fmt: skip
    assert pages == known, f"pages the matrix does not know: {pages - known}"


OPEN_READS = [op for op, kind in ROUTES.items() if kind == OPEN and op[0] == "GET"]


@pytest.mark.parametrize("method,path", OPEN_READS, ids=[p for _, p in OPEN_READS])
def test_an_open_route_answers_everyone_alike(site, method, path):
    answers = [site.call(method, path, caller) for caller in CALLERS]
    assert [r.status_code for r in answers] == [200] * len(CALLERS)
    if path != "/readyz":  # readiness carries the moment's checks
        assert all(r.content == answers[0].content for r in answers)


OWNED_READS = [op for op, kind in ROUTES.items() if kind == OWNED and op[0] == "GET"]


@pytest.mark.parametrize("method,path", OWNED_READS, ids=[p for _, p in OWNED_READS])
@pytest.mark.parametrize("owner", OWNERS)
def test_an_owned_object_is_read_by_its_owner_and_admins_only(site, method, path, owner):
    target = _fill(path, site.owned[owner])
    missing = _fill(path, Owned(10**6, 10**6, 10**6, 10**6))
    nobody = site.call(method, missing, "alice")
    assert nobody.status_code == 404
    for caller in CALLERS:
        r = site.call(method, target, caller)
        if caller is None:
            expected = 401
        elif caller in (owner, "admin"):
            expected = 200
        else:
            expected = 404
        assert r.status_code == expected, f"{caller} {target}: {r.status_code} {r.text[:200]}"
        if expected == 404:
            # the same answer as for an id that does not exist: ids reveal nothing
            assert _digits_out(r.json()["detail"]) == _digits_out(nobody.json()["detail"])


def _digits_out(text: str) -> str:
    return re.sub(r"\d+", "N", text)


@pytest.mark.parametrize("owner", OWNERS)
def test_a_job_is_cancelled_by_its_owner_or_an_admin_only(site, owner):
    for caller in CALLERS:
        job_id = site.new_queued_job(owner)
        r = site.call("POST", f"/api/v1/jobs/{job_id}/cancel", caller)
        allowed = caller in (owner, "admin")
        expected = 200 if allowed else (401 if caller is None else 404)
        assert r.status_code == expected, f"{caller}: {r.status_code} {r.text[:200]}"
        with session_scope(site.url) as s:
            job = s.get(Job, job_id)
            assert (job.status == "cancelled") == allowed, f"{caller} changed another's job"
            assert all((run.status == "cancelled") == allowed for run in job.runs)


@pytest.mark.parametrize("owner", OWNERS)
def test_jobs_are_submitted_on_your_own_worlds_only(site, owner):
    body = {"world_id": site.owned[owner].world, "runs": 1, "slam": "odometry"}
    for caller in CALLERS:
        with session_scope(site.url) as s:
            before = s.query(Job).count()
        r = site.call("POST", "/api/v1/jobs", caller, json=body)
        allowed = caller in (owner, "admin")
        expected = 202 if allowed else (401 if caller is None else 404)
        assert r.status_code == expected, f"{caller}: {r.status_code} {r.text[:200]}"
        with session_scope(site.url) as s:
            assert s.query(Job).count() == before + allowed
            if allowed:
                job = s.get(Job, r.json()["id"])
                assert job.owner_id == site.ids[caller]


def test_uploads_belong_to_the_uploader_and_need_a_key(site):
    for i, caller in enumerate(CALLERS):
        r = site.call(
            "POST", "/api/v1/worlds", caller, params={"wait": 30},
            files=[("file", (f"plan{i}.png", _png(_rooms()[:, : 130 + i]), "image/png"))],
            data={"resolution": "0.05"},
        )  # fmt: skip
        if caller is None:
            assert r.status_code == 401
            continue
        assert r.status_code == 201, r.text
        world_id = r.json()["id"]
        for other in CALLERS:
            seen = site.call("GET", f"/api/v1/worlds/{world_id}", other).status_code
            assert seen == (200 if other in (caller, "admin") else 401 if other is None else 404)


BUNDLED_READS = [op for op, kind in ROUTES.items() if kind == BUNDLED and op[0] == "GET"]
BUNDLED_WORLD = {"dataset": "bormann", "name": "Freiburg52_scan"}


@pytest.mark.parametrize("method,path", BUNDLED_READS, ids=[p for _, p in BUNDLED_READS])
def test_the_bundled_data_sets_answer_every_signed_in_user_alike(site, method, path):
    target = path.format(**BUNDLED_WORLD)
    answers = [site.call(method, target, caller) for caller in CALLERS]
    assert [r.status_code for r in answers] == [200, 200, 200, 401], target
    assert answers[0].content == answers[1].content == answers[2].content


def test_an_imported_world_belongs_to_the_importer(site):
    url = "/api/v1/datasets/{dataset}/worlds/{name}/import".format(**BUNDLED_WORLD)
    assert site.call("POST", url, None).status_code == 401
    for caller in ("alice", "bob", "admin"):
        r = site.call("POST", url, caller)
        assert r.status_code == 201, r.text
        world_id = r.json()["id"]
        for other in CALLERS:
            seen = site.call("GET", f"/api/v1/worlds/{world_id}", other).status_code
            assert seen == (200 if other in (caller, "admin") else 401 if other is None else 404)


def test_lists_show_your_own_objects_and_an_admin_everything(site):
    def ids_of(path, caller, key="id"):
        r = site.call("GET", path, caller)
        assert r.status_code == 200, r.text
        doc = r.json()
        items = doc["items"] if isinstance(doc, dict) else doc
        return {item[key] for item in items}

    for caller in CALLERS:
        for path in ("/api/v1/worlds", "/api/v1/jobs", "/api/v1/stats"):
            if caller is None:
                assert site.call("GET", path, None).status_code == 401
    for owner, other in (("alice", "bob"), ("bob", "alice")):
        mine, theirs = site.owned[owner], site.owned[other]
        worlds = ids_of("/api/v1/worlds", owner)
        assert mine.world in worlds and theirs.world not in worlds
        jobs = ids_of("/api/v1/jobs", owner)
        assert mine.job in jobs and theirs.job not in jobs
        stats = ids_of("/api/v1/stats", owner, "world_id")
        assert stats == {mine.world}
        # filtering by another owner's world shows nothing of theirs
        r = site.call("GET", "/api/v1/jobs", owner, params={"world_id": theirs.world})
        assert r.json()["items"] == []
    everything = ids_of("/api/v1/jobs", "admin")
    assert {o.job for o in site.owned.values()} <= everything


@pytest.mark.parametrize("page", OWNED_PAGES)
@pytest.mark.parametrize("owner", OWNERS)
def test_a_dashboard_page_of_an_object_is_shown_to_its_owner_and_admins_only(site, page, owner):
    target = _fill(page, site.owned[owner])
    for caller in CALLERS:
        r = site.call("GET", target, caller)
        if caller is None:
            assert r.status_code == 303 and r.headers["location"].startswith("/login")
        else:
            expected = 200 if caller in (owner, "admin") else 404
            assert r.status_code == expected, f"{caller} {target}: {r.status_code}"


@pytest.mark.parametrize("page", LIST_PAGES)
def test_dashboard_lists_show_your_own_objects(site, page):
    assert site.call("GET", page, None).status_code == 303
    for caller in ("alice", "bob", "admin"):
        assert site.call("GET", page, caller).status_code == 200
    home = site.call("GET", "/", "alice").text
    assert f'href="/jobs/{site.owned["alice"].job}"' in home
    assert f'href="/jobs/{site.owned["bob"].job}"' not in home


def test_the_explorer_lists_your_own_runs_only(site):
    """Every run row of the explorer's CSV is the caller's (an administrator's: everyone's)."""
    query = "applied=1&kind=completed&kind=incomplete&kind=time+limit&kind=failed"
    for caller, want in (("alice", {"alice"}), ("bob", {"bob"}), ("admin", {"alice", "bob"})):
        text = site.call("GET", f"/explore/runs.csv?{query}", caller).text
        listed = {int(line.split(",", 1)[0]) for line in text.splitlines()[1:]}
        for owner in ("alice", "bob"):
            assert (site.owned[owner].run in listed) == (owner in want), (caller, owner)


def test_no_run_row_was_changed_by_reading(site):
    with session_scope(site.url) as s:
        for owner in OWNERS:
            run = s.get(Run, site.owned[owner].run)
            assert run.status == "done" and run.owner_id == site.ids[owner]


def _viewer_links(html: str) -> dict[int, str]:
    """run id -> token of the viewer links on a dashboard page."""
    return {int(m[0]): m[1] for m in re.findall(r"/run/(\d+)/([A-Za-z0-9_.-]+)", html)}


@pytest.mark.parametrize("owner", OWNERS)
def test_the_viewer_admits_a_run_through_its_owners_or_an_admins_link_only(site, owner):
    from backend.core.viewer_tokens import InvalidToken, authorise, signing_key

    key = signing_key(site.url, None)
    run_id, other_run = site.owned[owner].run, site.owned[_other(owner)].run
    for caller in ("alice", "bob", "admin"):
        page = site.call("GET", f"/jobs/{site.owned[owner].job}", caller)
        if caller not in (owner, "admin"):
            assert page.status_code == 404 and not _viewer_links(page.text)
            continue
        links = _viewer_links(page.text)
        assert set(links) == {run_id}, links
        with session_scope(site.url) as s:
            grant = authorise(s, key, run_id, links[run_id])
            assert grant.user_id == site.ids[caller]
            # the same token opens no other run, and no token opens nothing
            for run, token in ((other_run, links[run_id]), (run_id, ""), (run_id, "1.2.x")):
                with pytest.raises(InvalidToken):
                    authorise(s, key, run, token)


def _other(owner: str) -> str:
    return "bob" if owner == "alice" else "alice"
