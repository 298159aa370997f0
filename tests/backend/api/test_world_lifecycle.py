"""An uploaded world's life: pending (202) -> ready or invalid, decided by its analysis;
`wait`; 409 for its image and its jobs until it is ready; worlds left pending are analysed
again when the API starts."""

from __future__ import annotations

import io
import os
import signal
import time
from pathlib import Path

import numpy as np
from fastapi.testclient import TestClient
from PIL import Image
from sqlalchemy import select

from backend.core.config import Settings
from backend.db.models import User, World
from backend.db.session import session_scope
from backend.services.world_analysis import WorldPool, pack_upload
from backend.store import create_pending_world
from mapqual.app import create_app


def _png(value: int | None = None, shape: tuple[int, int] = (40, 60)) -> bytes:
    img = np.full(shape, 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    if value is not None:
        img[:] = value
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def _upload(api, data: bytes, name="box.png", **params):
    return api.post(
        "/api/v1/worlds",
        files=[("file", (name, data, "image/png"))],
        data={"resolution": "0.05"},
        params=params,
    )


def _wait_done(api, world_id: int, seconds: float = 30.0) -> dict:
    deadline = time.monotonic() + seconds
    while (w := api.get(f"/api/v1/worlds/{world_id}").json())["status"] == "pending":
        assert time.monotonic() < deadline, "the analysis did not finish"
        time.sleep(0.1)
    return w


def test_a_world_is_pending_then_ready_and_usable_only_then(api):
    # 9 MP: analysed in the analysis process (past ANALYSE_AT_ONCE), for a second or more
    r = _upload(api, _png(shape=(3000, 3000)))
    assert r.status_code == 202, r.text
    w = r.json()
    assert w["status"] == "pending" and w["error"] is None
    assert w["width_px"] is None and w["start_pose"] is None and w["resolution"] is None
    image = api.get(f"/api/v1/worlds/{w['id']}/image")
    job = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1})
    # still pending after both requests means it was pending during them (status only moves
    # forward)
    assert api.get(f"/api/v1/worlds/{w['id']}").json()["status"] == "pending"
    assert image.status_code == 409 and "pending" in image.json()["detail"]
    assert job.status_code == 409 and "pending" in job.json()["detail"]
    assert api.get("/api/v1/jobs").json()["total"] == 0
    done = _wait_done(api, w["id"])
    assert done["status"] == "ready" and (done["width_px"], done["height_px"]) == (3000, 3000)
    assert done["facts"]["free_area_m2"] > 0 and len(done["start_pose"]) == 3
    assert api.get(f"/api/v1/worlds/{w['id']}/image").status_code == 200
    assert api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1}).status_code == 202
    with session_scope(api.url) as s:
        assert s.get(World, w["id"]).upload is None  # the upload is dropped once analysed


def test_wait_answers_the_outcome_ready_201_or_invalid_400_with_the_reason(api):
    r = _upload(api, _png(), wait=30)
    assert r.status_code == 201 and r.json()["status"] == "ready", r.text
    # the same content again: the existing world, answered at once
    again = _upload(api, _png(), wait=30)
    assert again.status_code == 200 and again.json()["id"] == r.json()["id"]
    # all black: passes the request's checks, refused by the analysis (no free cell)
    bad = _upload(api, _png(0), name="black.png", wait=30)
    assert bad.status_code == 400, bad.text
    assert "no free cell" in bad.json()["detail"] and "/tmp" not in bad.json()["detail"]
    wid = bad.json()["world"]["id"]
    w = api.get(f"/api/v1/worlds/{wid}").json()
    assert w["status"] == "invalid" and "no free cell" in w["error"]
    image = api.get(f"/api/v1/worlds/{wid}/image")
    assert image.status_code == 409 and "invalid" in image.json()["detail"]
    job = api.post("/api/v1/jobs", json={"world_id": wid, "runs": 1})
    assert job.status_code == 409 and "invalid" in job.json()["detail"]
    for wait in ("-1", "31", "soon"):
        r = _upload(api, _png(), name="other.png", wait=wait)
        assert r.status_code == 422 and "wait" in r.text


def test_worlds_left_pending_are_analysed_when_the_api_starts(api):
    # as a process that died after storing the upload, before its analysis finished
    with session_scope(api.url) as s:
        owner = s.scalars(select(User).where(User.name == "alice")).one().id
        ids = [
            create_pending_world(
                s, owner_id=owner, name=name, sha256=name * 8, source_format="image",
                source_path=f"{name}.png", upload=pack_upload({f"{name}.png": data}),
                resolution=0.05,
            ).id
            for name, data in (("good", _png()), ("dark", _png(0)))
        ]  # fmt: skip
    assert [api.get(f"/api/v1/worlds/{i}").json()["status"] for i in ids] == ["pending"] * 2
    settings = Settings(DATABASE_URL=api.url, MAPQUAL_AUTH="on")
    with TestClient(create_app(settings)):  # its start finds and analyses them
        good, dark = (_wait_done(api, i) for i in ids)
    assert good["status"] == "ready" and good["width_px"] == 60
    assert dark["status"] == "invalid" and "no free cell" in dark["error"]


def _analysis_processes() -> list[int]:
    """This process's analysis zygotes (`backend.sandbox.child analysis`)."""
    found = []
    for proc in Path("/proc").iterdir():
        try:
            stat = (proc / "stat").read_text()
            cmd = (proc / "cmdline").read_bytes()
        except OSError:
            continue
        ppid = int(stat[stat.rindex(")") + 2 :].split()[1])
        if ppid == os.getpid() and b"backend.sandbox.child\0analysis" in cmd:
            found.append(int(proc.name))
    return found


def test_an_analysis_process_that_dies_leaves_its_world_invalid_and_the_next_is_ready(api):
    pool = WorldPool(Settings(DATABASE_URL=api.url, MAPQUAL_AUTH="on"))
    with session_scope(api.url) as s:
        owner = s.scalars(select(User).where(User.name == "alice")).one().id
        ids = [
            create_pending_world(
                s, owner_id=owner, name=name, sha256=name * 8, source_format="image",
                source_path=f"{name}.png", resolution=0.05,
                # past ANALYSE_AT_ONCE: analysed in the analysis process, not where it is read
                upload=pack_upload({f"{name}.png": _png(shape=(1500, 1400))}),
            ).id
            for name in ("killed", "after")
        ]  # fmt: skip
    others = set(_analysis_processes())  # the api fixture's app's
    try:
        future = pool.submit(ids[0])
        # SIGKILL the analysis process while it is still starting (it loads for seconds)
        deadline = time.monotonic() + 30
        while not (pids := set(_analysis_processes()) - others):
            assert time.monotonic() < deadline and not future.done()
            time.sleep(0.01)
        for pid in pids:
            os.kill(pid, signal.SIGKILL)
        assert future.result(timeout=60) == "invalid"
        w = api.get(f"/api/v1/worlds/{ids[0]}").json()
        assert w["status"] == "invalid"
        assert w["error"] == "killed.png: could not be analysed (no parser process started)"
        assert pool.submit(ids[1]).result(timeout=90) == "ready"  # a fresh process
    finally:
        pool.shutdown()
    assert set(_analysis_processes()) <= others
