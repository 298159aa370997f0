"""Worlds and jobs over HTTP against a real database and a real Redis broker (no worker)."""

from __future__ import annotations

import io
import json
import struct
import zlib

import numpy as np
import pytest
from PIL import Image

from tests.summaries import make_summary, relation, stats


def _png(w=80, h=60, door=False) -> bytes:
    img = np.full((h, w), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:, w // 2] = 0
    img[h // 2 - 10 : h // 2 + 10, w // 2] = 255  # a 1 m wide doorway at 0.05 m/px
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def _bomb_png(w=100_000, h=100_000) -> bytes:
    """A valid PNG header claiming w x h pixels, with almost no data (a decompression bomb)."""

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))

    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", ihdr)
        + chunk(b"IDAT", zlib.compress(b"\0" * 64))
        + chunk(b"IEND", b"")
    )


def _upload(api, files, user="alice", **data):
    """Upload and wait (up to 30 s) for the analysis's outcome, as a client that needs it."""
    return api.post(
        "/api/v1/worlds",
        user=user,
        files=[("file", f) for f in files],
        data=data,
        params={"wait": 30},
    )


def test_upload_an_image_then_the_same_again_returns_the_existing_world(api):
    r1 = _upload(api, [("box.png", _png(), "image/png")], resolution="0.05")
    assert r1.status_code == 201, r1.text
    w = r1.json()
    assert (w["width_px"], w["height_px"], w["resolution"]) == (80, 60, 0.05)
    assert w["width_m"] == pytest.approx(4.0) and w["height_m"] == pytest.approx(3.0)
    assert len(w["start_pose"]) == 3 and w["facts"]["free_area_m2"] > 0
    r2 = _upload(api, [("box.png", _png(), "image/png")], resolution="0.05")
    assert r2.status_code == 200 and r2.json()["id"] == w["id"]
    img = api.get(f"/api/v1/worlds/{w['id']}/image")
    assert img.headers["content-type"] == "image/png"
    pixels = np.asarray(Image.open(io.BytesIO(img.content)))
    assert pixels.shape == (60, 80) and pixels[0, 0] == 0 and pixels[5, 5] == 255
    assert [x["id"] for x in api.get("/api/v1/worlds").json()] == [w["id"]]


def test_a_thumbnail_keeps_one_pixel_walls(api):
    w = _upload(api, [("box.png", _png(), "image/png")], resolution="0.05").json()
    # 80 x 60 px with max 16: blocks of 5 x 5 px, 16 x 12 of them. The walls are one pixel
    # wide: the border rows and columns and column 40 (block 8, as 40 // 5 = 8) with its
    # doorway at rows 20..39 (blocks 4..7, which hold no wall pixel of that column)
    img = api.get(f"/api/v1/worlds/{w['id']}/image", params={"max_px": 16})
    thumb = np.asarray(Image.open(io.BytesIO(img.content)))
    assert thumb.shape == (12, 16)
    wall = thumb == 0
    assert wall[[0, -1], :].all() and wall[:, [0, -1]].all()
    assert wall[1:4, 8].all() and wall[8:11, 8].all() and not wall[4:8, 8].any()
    assert not wall[1:11, 1:8].any() and not wall[1:11, 9:15].any()
    for bad in ("3", "100000", "big"):
        r = api.get(f"/api/v1/worlds/{w['id']}/image", params={"max_px": bad})
        assert r.status_code == 422 and "max_px" in r.text


def test_upload_a_map_server_yaml_with_its_image(api):
    yaml = (
        b"image: box.png\nresolution: 0.1\norigin: [-2.0, -1.0, 0.0]\nnegate: 0\n"
        b"occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    r = _upload(api, [("box.yaml", yaml, "application/yaml"), ("box.png", _png(), "image/png")])
    assert r.status_code == 201, r.text
    assert r.json()["origin"] == [-2.0, -1.0] and r.json()["resolution"] == 0.1


@pytest.mark.parametrize(
    ("files", "data", "code", "needle"),
    [
        ([("box.png", _png(), "image/png")], {}, 400, "resolution"),
        (
            [("notes.png", b"this is not an image", "image/png")],
            {"resolution": "0.05"},
            400,
            "not a readable image",
        ),
        ([("bomb.png", _bomb_png(), "image/png")], {"resolution": "0.05"}, 413, "bomb.png: "),
        ([("box.png", _png(), "image/png")], {"resolution": "5"}, 400, "resolution"),
        ([("box.png", _png(), "image/png")], {"resolution": "-1"}, 422, "resolution"),
        ([("../../etc/x.png", _png(), "image/png")], {"resolution": "0.05"}, 201, ""),
        (
            [("a.yaml", b"image: missing.png\nresolution: 0.05\n", "text/plain")],
            {},
            400,
            "missing.png",
        ),
        (
            [("a.png", _png(), "image/png"), ("b.png", _png(), "image/png")],
            {"resolution": "0.05"},
            400,
            "upload one image",
        ),
    ],
)
def test_bad_uploads_get_a_4xx_with_a_message_and_store_nothing(api, files, data, code, needle):
    r = _upload(api, files, **data)
    assert r.status_code == code, r.text
    if code >= 400:
        detail = json.dumps(r.json()["detail"])
        assert needle in detail
        assert "/tmp" not in detail  # the server's paths are not the user's business
        assert api.get("/api/v1/worlds").json() == []


def test_oversized_upload_is_413(api):
    big = b"\0" * (21 * 1024 * 1024)
    r = _upload(api, [("big.png", big, "image/png")], resolution="0.05")
    assert r.status_code == 413 and "larger than" in r.json()["detail"]


def _world(api, user="alice"):
    return _upload(api, [("box.png", _png(), "image/png")], user=user, resolution="0.05").json()


def test_submit_a_job_queues_one_message_per_run_and_honours_the_idempotency_key(api):
    w = _world(api)
    body = {
        "world_id": w["id"],
        "seeds": [3, 5, 8],
        "slam": "odometry",
        "params": {"slam": {"particles": 7}},
    }
    r = api.post("/api/v1/jobs", json=body, headers={"Idempotency-Key": "abc"})
    assert r.status_code == 202, r.text
    job = r.json()
    assert [x["seed"] for x in job["runs"]] == [3, 5, 8]
    assert {x["status"] for x in job["runs"]} == {"queued"} and job["status"] == "queued"
    assert job["slam"] == "odometry" and job["params"]["slam"]["particles"] == 7
    assert api.broker.llen("mapqual") == 3  # real messages on the real broker
    again = api.post("/api/v1/jobs", json=body, headers={"Idempotency-Key": "abc"})
    assert again.status_code == 202 and again.json()["id"] == job["id"]
    assert api.broker.llen("mapqual") == 3
    got = api.get(f"/api/v1/jobs/{job['id']}").json()
    assert [x["id"] for x in got["runs"]] == [x["id"] for x in job["runs"]]
    page = api.get("/api/v1/jobs", params={"status": "queued", "world_id": w["id"]}).json()
    assert page["total"] == 1 and page["items"][0]["id"] == job["id"]


def test_runs_count_gives_seeds_one_to_n_and_cancel_stops_them(api):
    w = _world(api)
    job = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 2}).json()
    assert [x["seed"] for x in job["runs"]] == [1, 2] and job["slam"] == "rbpf"
    c = api.post(f"/api/v1/jobs/{job['id']}/cancel")
    assert c.status_code == 200 and c.json()["status"] == "cancelled"
    assert {x["status"] for x in c.json()["runs"]} == {"cancelled"}
    assert api.post(f"/api/v1/jobs/{job['id']}/cancel").status_code == 409


@pytest.mark.parametrize(
    ("body", "code", "needle"),
    [
        ({"runs": 2, "seeds": [1]}, 422, "exactly one"),
        ({}, 422, "exactly one"),
        ({"runs": 0}, 422, "greater than or equal to 1"),
        ({"runs": 1, "slam": "ekf"}, 422, "rbpf"),
        ({"runs": 1, "params": {"slam": {"particles": 0}}}, 400, "particles"),
        ({"runs": 1, "params": {"slam": {"particle": 3}}}, 400, "unknown parameter slam.particle"),
        ({"runs": 1, "params": {"sim": {"laser_noise_sigma": "high"}}}, 400, "must be a number"),
        ({"seeds": [1, 1]}, 422, "duplicates"),
        ({"runs": 1, "colour": "red"}, 422, "colour"),
    ],
)
def test_bad_jobs_get_a_4xx_with_a_message_and_store_nothing(api, body, code, needle):
    w = _world(api)
    r = api.post("/api/v1/jobs", json={"world_id": w["id"], **body})
    assert r.status_code == code, r.text
    assert needle in json.dumps(r.json()["detail"])
    assert api.get("/api/v1/jobs").json()["total"] == 0
    assert api.broker.llen("mapqual") == 0


def test_other_owners_resources_are_404_and_admin_sees_them(api):
    w = _world(api, user="alice")
    job = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1}).json()
    run_id = job["runs"][0]["id"]
    for path in (
        f"/api/v1/worlds/{w['id']}",
        f"/api/v1/worlds/{w['id']}/image",
        f"/api/v1/jobs/{job['id']}",
        f"/api/v1/runs/{run_id}",
    ):
        assert api.get(path, user="bob").status_code == 404, path
        assert api.get(path, user="admin").status_code == 200, path
    assert (
        api.post("/api/v1/jobs", user="bob", json={"world_id": w["id"], "runs": 1}).status_code
        == 404
    )
    assert api.post(f"/api/v1/jobs/{job['id']}/cancel", user="bob").status_code == 404
    assert api.get("/api/v1/jobs", user="bob").json()["total"] == 0
    assert api.get("/api/v1/worlds", user="bob").json() == []


def test_results_of_an_unfinished_run_are_404(api):
    w = _world(api)
    run_id = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1}).json()["runs"][0]["id"]
    assert api.get(f"/api/v1/runs/{run_id}").json()["status"] == "queued"
    for path in ("trajectory", "map.png", "relations", "report.zip"):
        r = api.get(f"/api/v1/runs/{run_id}/{path}")
        assert r.status_code == 404 and r.json()["detail"]


def test_unreachable_broker_is_503_and_stores_no_job(api):
    from fastapi.testclient import TestClient

    from backend.core.config import Settings
    from mapqual.app import create_app

    w = _world(api)
    settings = Settings(DATABASE_URL=api.url, REDIS_URL="redis://127.0.0.1:1/0")
    with TestClient(create_app(settings)) as client:
        headers = {"Authorization": f"Bearer {api.keys['alice']}"}
        r = client.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1}, headers=headers)
    assert r.status_code == 503 and "unreachable" in r.json()["detail"]
    # the broker is asked for its epoch before anything is stored: nothing to clean up, and
    # the same request sent again later makes the job
    assert api.get("/api/v1/jobs").json()["items"] == []


def test_a_finished_run_without_its_report_folder_serves_its_map_from_the_database(api):
    from backend.db.session import session_scope
    from backend.store import mark_run_started, store_run_result

    w = _world(api)
    run_id = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1}).json()["runs"][0]["id"]
    grid = np.full((40, 60), -1, dtype=np.int8)  # [iy, ix], bottom row first
    grid[:20, :] = 0  # lower half free
    grid[0, :] = 100  # bottom row a wall
    t = np.arange(5) * 0.1
    poses = np.zeros((5, 3))
    b = stats(0.25, 0.125, 7, min=0.0, max=1.0)
    summary = make_summary(
        world="box",
        seed=1,
        outcome="completed",
        reason=None,
        stop="no_frontier",
        coverage=0.5,
        relations={"B": relation(b)},
        timings={"sim_time_s": 0.4, "wall_time_s": 1.0},
    )
    with session_scope(api.url) as s:
        mark_run_started(s, run_id)
        store_run_result(
            s, run_id, summary=summary, t=t, pose_gt=poses, pose_est=poses, map_ros=grid,
            map_resolution=0.05, map_origin=(1.0, 2.0), report_dir=None,
        )  # fmt: skip
    pgm = api.get(f"/api/v1/runs/{run_id}/map.pgm").content
    header, pixels = pgm.split(b"\n255\n", 1)
    assert header.endswith(b"60 40")
    img = np.frombuffer(pixels, np.uint8).reshape(40, 60)  # top row first, as map_saver writes
    assert (img[-1] == 0).all() and (img[-2] == 254).all() and (img[0] == 205).all()
    # the report folder's writer (worker.slam.grid.map_server_files), at its precision
    yaml_text = api.get(f"/api/v1/runs/{run_id}/map.yaml").text
    assert "resolution: 0.050000\norigin: [1.000000, 2.000000, 0.000000]\n" in yaml_text
    png = api.get(f"/api/v1/runs/{run_id}/map.png")
    assert png.status_code == 200 and png.headers["content-type"] == "image/png"
    rgb = np.asarray(Image.open(io.BytesIO(png.content)).convert("RGB"))
    assert rgb.shape[1] >= 640  # scaled up for the text
    assert ((rgb[..., 0] > 120) & (rgb[..., 1] < 40)).any()  # the errors are written in red


def test_a_job_reads_the_same_by_id_as_in_the_list_and_follows_its_runs(api):
    # GET /jobs/{id} reads columns directly; GET /jobs builds the same answer from ORM objects
    from backend.db.session import session_scope
    from backend.store import mark_run_started, store_run_result

    w = _world(api)
    job = api.post("/api/v1/jobs", json={"world_id": w["id"], "seeds": [9, 4, 6]}).json()
    first = api.get(f"/api/v1/jobs/{job['id']}").json()
    # the same answer, times included, in UTC with its zone on both databases (SQLite keeps no
    # zone: the column type puts UTC back)
    assert first == job and job["created_at"].endswith("Z") and job["updated_at"].endswith("Z")
    listed = api.get("/api/v1/jobs").json()["items"]
    assert [j["created_at"] for j in listed] == [job["created_at"]]
    done, running, _ = (r["id"] for r in job["runs"])
    b = stats(0.5, 0.1, 3, min=0.25, max=0.75)
    with session_scope(api.url) as s:
        mark_run_started(s, running).progress = {"t": 12.5, "coverage": 0.25, "pose": [1, 2, 0]}
        mark_run_started(s, done)
        store_run_result(
            s, done, summary=make_summary(outcome="completed", reason=None, coverage=0.875,
                                          stop="no_frontier", relations={"B": relation(b)}),
            t=np.zeros(2), pose_gt=np.zeros((2, 3)), pose_est=np.zeros((2, 3)),
            map_ros=np.zeros((2, 2), np.int8), map_resolution=0.05, map_origin=(0, 0),
            report_dir=None,
        )  # fmt: skip
    got = api.get(f"/api/v1/jobs/{job['id']}").json()
    assert got == api.get("/api/v1/jobs").json()["items"][0]
    assert got["status"] == "running" and got["updated_at"] > first["updated_at"]
    assert [r["seed"] for r in got["runs"]] == [9, 4, 6]  # in the order they were made
    assert [r["status"] for r in got["runs"]] == ["done", "running", "queued"]
    assert got["runs"][0]["outcome"] == "completed" and got["runs"][0]["b_mean_t"] == 0.5
    assert got["runs"][0]["coverage"] == 0.875
    assert got["runs"][1]["progress"] == {"t": 12.5, "coverage": 0.25, "pose": [1, 2, 0]}
    assert got["runs"][2]["progress"] == {} and got["runs"][2]["outcome"] is None
    assert api.get(f"/api/v1/jobs/{job['id'] + 1}").status_code == 404


def test_openapi_documents_the_job_answers_that_are_sent_as_ready_json(api):
    doc = api.client.get("/api/v1/openapi.json").json()
    ref = {"$ref": "#/components/schemas/JobOut"}
    post = doc["paths"]["/api/v1/jobs"]["post"]
    assert post["responses"]["202"]["content"]["application/json"]["schema"] == ref
    assert post["requestBody"]["content"]["application/json"]["schema"]["$ref"].endswith("/JobIn")
    get = doc["paths"]["/api/v1/jobs/{job_id}"]["get"]
    assert get["responses"]["200"]["content"]["application/json"]["schema"] == ref
    assert "runs" in doc["components"]["schemas"]["JobOut"]["properties"]
