"""The API publishes the run summary's JSON Schema, and a run's `summary` is that model."""

from __future__ import annotations

import numpy as np
from sqlalchemy import select

from backend.db.models import User
from backend.db.session import session_scope
from backend.store import create_job, mark_run_started, save_world, store_run_result
from tests.backend.plans import rooms_occupancy
from tests.summaries import make_summary, summary_doc
from worker.report.summary import RunSummary
from worker.world.world import World


def test_the_summary_schema_is_published_to_anyone(api):
    r = api.get("/api/v1/schemas/summary", user=None)
    assert r.status_code == 200
    schema = r.json()
    assert schema == RunSummary.model_json_schema()
    assert schema["title"] == "RunSummary" and "relations" in schema["required"]
    assert schema["$defs"]["ErrorStats"]["required"] == [
        "mean", "std", "min", "max", "n", "mean_squared"
    ]  # fmt: skip


def test_the_run_answer_refers_to_the_summary_model_in_openapi(api):
    doc = api.get("/api/v1/openapi.json").json()
    components = doc["components"]["schemas"]
    summary = components["RunOut"]["properties"]["summary"]
    refs = [s.get("$ref") for s in summary["anyOf"]]
    assert "#/components/schemas/RunSummary" in refs and {"type": "null"} in summary["anyOf"]
    assert set(components["RunSummary"]["properties"]) == set(
        RunSummary.model_json_schema()["properties"]
    )


def _world_and_job(api) -> tuple[int, int]:
    """alice's world and a job of two runs on it: (the first run, the second)."""
    with session_scope(api.url) as s:
        owner = s.scalars(select(User).where(User.name == "alice")).one().id
        world = World.from_array(rooms_occupancy(1, 1), 0.05, name="room")
        w = save_world(s, owner_id=owner, world=world, sha256="room", source_format="image")
        job = create_job(s, owner_id=owner, world_id=w.id, slam="odometry", params={}, seeds=[1, 2])
        return job.runs[0].id, job.runs[1].id


def test_a_run_shows_its_stored_summary_with_its_version_and_none_before(api):
    done, queued = _world_and_job(api)
    with session_scope(api.url) as s:
        mark_run_started(s, done)
        store_run_result(
            s, done, summary=make_summary(), t=np.zeros(2), pose_gt=np.zeros((2, 3)),
            pose_est=np.zeros((2, 3)), map_ros=np.zeros((2, 2), np.int8), map_resolution=0.05,
            map_origin=(0, 0), report_dir=None,
        )  # fmt: skip
    got = api.get(f"/api/v1/runs/{done}").json()
    # the stored summary.json as it is, and the version the API states
    assert got["summary"] == {"schema_version": 1, **summary_doc()}
    assert got["metrics"]["relations"] == summary_doc()["relations"]
    assert api.get(f"/api/v1/runs/{queued}").json()["summary"] is None
