"""The bundled data sets over HTTP, with the real worlds/ folder (loaded once per test process)
on a real database: the list with counts and licences, thumbnails, imports (once per owner,
ready, usable by a job at once), and names that are not in the catalogue."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from PIL import Image

from backend.db.models import Job, World
from backend.db.session import session_scope
from tests.backend.api.conftest import serving
from worker.world import load_world

WORLDS = Path(__file__).resolve().parents[3] / "worlds"
SMALL = ("bormann", "Freiburg52_scan")  # 643 x 354 px: the quickest to load again


def _expected() -> dict[str, set[str]]:
    """The plans of each data set, from its folder's YAML files (not from the code tested)."""
    return {
        name: {p.stem for p in (WORLDS / name).glob("*.yaml")} for name in ("bormann", "schools")
    }


def test_the_bundled_data_sets_are_listed_with_their_worlds_and_licences(api):
    r = api.get("/api/v1/datasets")
    assert r.status_code == 200, r.text
    sets = {d["name"]: d for d in r.json()}
    expected = _expected()
    assert {k: len(v) for k, v in expected.items()} == {"bormann": 32, "schools": 31}
    assert set(sets) == set(expected)
    for name, stems in expected.items():
        assert {w["name"] for w in sets[name]["worlds"]} == stems
        assert sets[name]["problems"] == []
    assert sets["bormann"]["licence_file"] == "SOURCE.md" and "LGPL" in sets["bormann"]["licence"]
    assert sets["schools"]["licence_file"] == "LICENSE" and sets["schools"]["licence"] == "MIT"
    text = api.get(sets["schools"]["licence_url"])
    assert text.status_code == 200 and "MIT License" in text.text
    assert text.headers["content-type"].startswith("text/plain")
    assert "LGPL" in api.get(sets["bormann"]["licence_url"]).text
    # the facts are load_world's
    (listed,) = [w for w in sets[SMALL[0]]["worlds"] if w["name"] == SMALL[1]]
    world = load_world(WORLDS / SMALL[0] / f"{SMALL[1]}.yaml")
    assert listed["facts"]["free_area_m2"] == pytest.approx(world.facts.free_area_m2)
    assert (listed["width_px"], listed["height_px"]) == (world.occ.shape[1], world.occ.shape[0])
    assert listed["start_pose"] == pytest.approx(list(world.start_pose))
    assert api.get("/api/v1/datasets", user=None).status_code == 401


def test_a_bundled_worlds_picture_and_thumbnail(api):
    url = "/api/v1/datasets/{}/worlds/{}/image".format(*SMALL)
    full = api.get(url)
    assert full.status_code == 200 and full.headers["content-type"] == "image/png"
    assert Image.open(io.BytesIO(full.content)).size == (643, 354)
    thumb = api.get(url, params={"max_px": 64})
    # reduced by a whole factor, ceil(643 / 64) = 11: 59 x 33 px
    assert Image.open(io.BytesIO(thumb.content)).size == (59, 33)
    assert api.get(url, params={"max_px": 3}).status_code == 422
    assert api.get(url, user=None).status_code == 401


def test_an_import_is_a_ready_world_of_yours_once_and_a_job_runs_on_it(api):
    url = "/api/v1/datasets/{}/worlds/{}/import".format(*SMALL)
    r = api.post(url)
    assert r.status_code == 201, r.text
    w = r.json()
    assert w["status"] == "ready" and w["name"] == SMALL[1] and w["width_px"] == 643
    again = api.post(url)
    assert again.status_code == 200 and again.json()["id"] == w["id"]
    assert [x["id"] for x in api.get("/api/v1/worlds").json()] == [w["id"]]
    theirs = api.post(url, user="bob")
    assert theirs.status_code == 201 and theirs.json()["id"] != w["id"]
    assert api.get(f"/api/v1/worlds/{w['id']}", user="bob").status_code == 404
    job = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1, "slam": "odometry"})
    assert job.status_code == 202, job.text
    with session_scope(api.url) as s:
        row = s.get_one(Job, job.json()["id"])
        assert row.world_id == w["id"] and len(row.runs) == 1
        assert s.get_one(World, w["id"]).source_path.endswith("Freiburg52_scan.yaml")
    assert api.post(url, user=None).status_code == 401


HOSTILE = [
    "/api/v1/datasets/nope/worlds/office_a/import",
    "/api/v1/datasets/bormann/worlds/nope/import",
    "/api/v1/datasets/bormann/worlds/office_a.yaml/import",
    "/api/v1/datasets/bormann/worlds/..%2Fschools%2FBorchen4/import",
    "/api/v1/datasets/bormann/worlds/no_furniture%2Foffice_a/import",
    "/api/v1/datasets/bormann/worlds/%2Fetc%2Fpasswd/import",
    "/api/v1/datasets/%2E%2E/worlds/bormann%2Foffice_a/import",
    "/api/v1/datasets/bormann%2F..%2Fschools/worlds/Borchen4/import",
]


def test_names_not_in_the_catalogue_answer_404_and_store_nothing(api):
    for path in HOSTILE:
        for r in (api.post(path), api.get(path.replace("/import", "/image"))):
            assert r.status_code == 404, f"{path}: {r.text}"
            # the catalogue's answer, or the router's when the decoded path fits no route
            detail = r.json()["detail"]
            assert detail.startswith(("no bundled data set", "no world", "Not Found")), detail
    assert api.get("/api/v1/datasets/nope/licence").status_code == 404
    with session_scope(api.url) as s:
        assert s.query(World).count() == 0


def test_a_new_import_counts_against_the_world_quota(db_url):
    with serving(db_url, MAPQUAL_QUOTA_WORLDS=1) as api:
        first = "/api/v1/datasets/{}/worlds/{}/import".format(*SMALL)
        assert api.post(first).status_code == 201
        r = api.post("/api/v1/datasets/bormann/worlds/Freiburg52_scan_furnitures/import")
        assert r.status_code == 429 and "quota_worlds" in r.json()["detail"]
        assert api.post(first).status_code == 200  # the one you have: no quota needed
