"""The API process stays light: no numba kernels imported to serve or to validate a job, and
the job body publishes RunParams' schema and the registry's SLAM names."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from worker.slam import registry

ROOT = Path(__file__).resolve().parents[3]

_SCRIPT = """
import json, sys
from fastapi.testclient import TestClient
from backend.core.config import Settings
from mapqual.app import create_app

def numba_modules():
    return sorted(m for m in sys.modules if m.split(".")[0] in ("numba", "llvmlite"))

seen = {"import": numba_modules()}
args = json.loads(sys.argv[1])
settings = Settings(DATABASE_URL=args["url"], REDIS_URL=args["redis"], MAPQUAL_AUTH="on")
auth = {"Authorization": "Bearer " + args["key"]}
with TestClient(create_app(settings)) as client:
    ok = client.post("/api/v1/jobs", headers=auth, json=args["body"])
    bad = client.post("/api/v1/jobs", headers=auth, json=args["bad"])
    seen["codes"] = [ok.status_code, bad.status_code]
    seen["bad"] = bad.json()["detail"]
    seen["params"] = ok.json()["params"]
seen["post"] = numba_modules()
print(json.dumps(seen))
"""


def _png() -> bytes:
    img = np.full((60, 80), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def test_import_and_post_jobs_leave_numba_out_of_the_api_process(api):
    # the world is uploaded (and analysed) by this test process; the fresh interpreter below
    # only imports the app and submits jobs, as the API process does
    up = api.post(
        "/api/v1/worlds",
        files=[("file", ("box.png", _png(), "image/png"))],
        data={"resolution": "0.05"},
        params={"wait": 30},
    )
    assert up.status_code == 201, up.text
    body = {"world_id": up.json()["id"], "runs": 1, "slam": "odometry"}
    args = {
        "url": api.url,
        "redis": _redis_url(api),
        "key": api.keys["alice"],
        "body": {**body, "params": {"explore": {"time_limit": 30}}},
        "bad": {**body, "params": {"slam": {"particles": 0}}},
    }
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", _SCRIPT, json.dumps(args)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert seen["import"] == [] and seen["post"] == [], seen
    assert seen["codes"] == [202, 400] and "particles" in seen["bad"]
    assert seen["params"]["explore"]["time_limit"] == 30.0
    assert seen["params"]["algorithm"] == "odometry"


def _redis_url(api) -> str:
    kw = api.broker.connection_pool.connection_kwargs
    return f"redis://{kw['host']}:{kw['port']}/{kw['db']}"


def test_openapi_job_body_has_the_run_params_schema_and_the_registry_enum(api):
    doc = api.client.get("/api/v1/openapi.json").json()
    job_in = doc["components"]["schemas"]["JobIn"]["properties"]
    slam = job_in["slam"]["anyOf"][0]
    assert (
        slam["enum"]
        == list(registry.names())
        == ["rbpf", "odometry", "oracle", "graph", "external"]
    )
    params = job_in["params"]
    assert params["additionalProperties"] is False
    assert set(params["properties"]) == {"algorithm", "sim", "slam", "explore", "eval", "realtime"}
    particles = params["properties"]["slam"]["properties"]["particles"]
    assert particles == {"default": 40, "title": "Particles", "type": "integer"}
    # the derived half footprint is stored with a run but is no parameter of its own
    assert (
        "footprint_half_m"
        not in params["properties"]["explore"]["properties"]["costmap"]["properties"]
    )
    assert "required" not in params["properties"]["sim"]  # partial overrides are fine


def test_partial_params_keep_their_defaults_as_before(api):
    up = api.post(
        "/api/v1/worlds",
        files=[("file", ("box.png", _png(), "image/png"))],
        data={"resolution": "0.05"},
        params={"wait": 30},
    )
    body = {"world_id": up.json()["id"], "runs": 1, "params": {"slam": {"particles": 7}}}
    job = api.post("/api/v1/jobs", json=body).json()
    assert job["slam"] == "rbpf" and job["params"]["slam"]["particles"] == 7
    assert job["params"]["slam"]["delta"] == 0.05 and job["params"]["sim"]["footprint"] == 0.4
    assert job["params"]["explore"]["costmap"]["footprint_half_m"] == 0.2


def test_a_job_with_the_flat_explore_keys_of_before_the_groups_is_stored_nested(api):
    up = api.post(
        "/api/v1/worlds",
        files=[("file", ("box.png", _png(), "image/png"))],
        data={"resolution": "0.05"},
        params={"wait": 30},
    )
    flat = {"door_align": True, "trail_cap": 150, "time_limit": 60.0}
    body = {"world_id": up.json()["id"], "runs": 1, "params": {"explore": flat}}
    explore = api.post("/api/v1/jobs", json=body).json()["params"]["explore"]
    assert explore["doors"]["door_align"] is True and explore["recovery"]["trail_cap"] == 150
    assert explore["time_limit"] == 60.0 and "door_align" not in explore
