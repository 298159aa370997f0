"""External SLAM over the API: users pick the administrator's programs by name; a command in
a request is refused (400) and nothing is stored or queued."""

from __future__ import annotations

import json

import pytest
from sqlalchemy import select

from backend.core.config import Settings
from backend.db.models import Run
from backend.db.session import session_scope
from tests.backend.api.conftest import serving
from tests.backend.api.test_worlds_jobs import _world

PROGRAMS = {"deadreck": ["/usr/bin/python3", "/opt/slam/dead_reckoning_slam.py"]}


@pytest.fixture
def api(db_url):
    with serving(db_url, MAPQUAL_EXTERNAL_SLAM=PROGRAMS) as served:
        yield served


def _job(api, external, slam="external"):
    w = _world(api)
    body = {
        "world_id": w["id"],
        "runs": 1,
        "slam": slam,
        "params": {"slam": {"external": external}},
    }
    return api.post("/api/v1/jobs", json=body)


@pytest.mark.parametrize(
    ("external", "needle"),
    [
        (
            {"name": "mine", "command": ["/bin/sh", "-c", "touch /tmp/pwned"]},
            "cannot be given over the API: the server runs only the programs its administrator "
            "registered; give slam.external.name, one of: 'deadreck'",
        ),
        ({"name": "deadreck", "command": ["/bin/sh"]}, "cannot be given over the API"),
        ({"name": "deadreck", "command": []}, "cannot be given over the API"),
        ({"name": "other"}, "'other' is not a registered program: 'deadreck'"),
        ("deadreck", "slam.external must be a mapping"),
        ({"name": "deadreck", "memory_mb": 10**9}, "memory_mb cannot be given over the API"),
        ({"name": "deadreck", "cpu_s": 10**9}, "cpu_s cannot be given over the API"),
        (
            {"name": "deadreck", "step_timeout_s": 1e300},
            "slam.external.step_timeout_s = 1e+300 s is over this server's cap of 60 s "
            "(setting external_step_timeout_max_s, environment "
            "MAPQUAL_EXTERNAL_STEP_TIMEOUT_MAX)",
        ),
        ({"name": "deadreck", "start_timeout_s": 121}, "cap of 120 s"),
        ({"name": "deadreck", "close_timeout_s": 10.5}, "cap of 10 s"),
        ({"name": "deadreck", "close_timeout_s": "9"}, "must be a number [s]"),
    ],
)
def test_a_user_cannot_make_the_server_run_a_command(api, external, needle):
    r = _job(api, external)
    assert r.status_code == 400, r.text
    assert needle in r.json()["detail"]
    assert api.get("/api/v1/jobs").json()["total"] == 0
    assert api.broker.llen("mapqual") == 0


def test_a_registered_program_is_picked_by_name_and_stored_with_its_command(api):
    r = _job(api, {"name": "deadreck", "step_timeout_s": 5.0})
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["slam"] == "external:deadreck"  # the program by its name (runs and jobs alike)
    want = {
        "name": "deadreck",
        "command": PROGRAMS["deadreck"],
        "start_timeout_s": 30.0,
        "step_timeout_s": 5.0,
        "close_timeout_s": 2.0,
        "memory_mb": 4096,
        "cpu_s": 7200,
    }  # fmt: skip  (the server's limits, filled in)
    assert job["params"]["slam"]["external"] == want
    with session_scope(api.url) as s:  # what the worker will read
        ((params, slam),) = s.execute(select(Run.params, Run.slam)).all()
    assert params["slam"]["external"] == want and params["algorithm"] == "external"
    assert slam == "external:deadreck"
    assert api.broker.llen("mapqual") == 1


def test_the_external_algorithm_needs_its_section(api):
    w = _world(api)
    r = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1, "slam": "external"})
    assert r.status_code == 400
    assert r.json()["detail"] == (
        "the external algorithm runs a program the administrator registered: give "
        "params.slam.external.name, one of: 'deadreck'"
    )


def test_the_administrator_lists_the_programs_in_the_environment(monkeypatch):
    monkeypatch.setenv("MAPQUAL_EXTERNAL_SLAM", json.dumps(PROGRAMS))
    assert Settings().external_slam == PROGRAMS
    monkeypatch.delenv("MAPQUAL_EXTERNAL_SLAM")
    assert Settings().external_slam == {}
