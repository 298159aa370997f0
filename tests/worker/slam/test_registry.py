"""The SLAM registry: one call adds an algorithm everywhere the choices are read."""

from __future__ import annotations

import pytest

from worker.errors import InputError
from worker.slam import registry
from worker.slam.odometry import OdometrySlam
from worker.slam.registry import make_slam


@pytest.fixture
def scratch_registry(monkeypatch):
    """The registry as it is, restored after the test (registrations are process-wide)."""
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_the_built_in_algorithms_and_their_kinds():
    assert registry.names() == ("rbpf", "odometry", "oracle", "graph", "external")
    # MRPT's programs (issue 51) replay logs only: `mapqual slam` offers them, a run does not
    assert registry.names(offline=True) == (
        "rbpf", "odometry", "graph", "external", "mrpt_rbpf", "mrpt_icp",
    )  # fmt: skip
    with pytest.raises(ValueError, match="replays recorded logs only"):
        registry.check_name("mrpt_rbpf")
    kinds = {e.name: (e.kind, e.ground_truth) for e in registry.entries()}
    assert kinds == {
        "rbpf": ("slam", False),
        "odometry": ("baseline", False),
        "oracle": ("oracle", True),
        "graph": ("slam", False),
        "external": ("slam", False),
        "mrpt_rbpf": ("slam", False),
        "mrpt_icp": ("slam", False),
    }
    with pytest.raises(InputError, match="unknown SLAM algorithm 'ekf'; choose one of: rbpf"):
        registry.get("ekf")


def test_one_register_call_reaches_params_schema_batch_and_factory(scratch_registry):
    from mapqual.cli.run import build_params
    from worker.batch.experiment import _slam
    from worker.run_params import RunParams, run_params_schema
    from worker.sim.laser import LaserSpec

    made = []

    def factory(laser, params, rng):
        made.append((laser, params))
        return OdometrySlam(laser, params)

    with pytest.raises(InputError, match="algorithm"):
        RunParams.from_json({"algorithm": "plugin"})
    registry.register("plugin", factory, "a plugin SLAM", "slam")
    assert "plugin" in registry.names() and "plugin" in registry.names(offline=True)
    assert RunParams.from_json({"algorithm": "plugin"}).algorithm == "plugin"
    assert build_params(None, "plugin", None, None).algorithm == "plugin"
    assert _slam("plugin") == "plugin"
    assert "plugin" in run_params_schema()["properties"]["algorithm"]["enum"]
    slam = make_slam("plugin", LaserSpec())
    assert isinstance(slam, OdometrySlam) and len(made) == 1
    with pytest.raises(ValueError, match="already registered"):
        registry.register("plugin", factory, "again")


def test_the_dashboard_form_lists_the_registry(scratch_registry):
    from frontend.dashboard.pages import templates

    registry.register("plugin", lambda laser, p, rng: None, "a plugin SLAM")
    html = templates.get_template("jobs.html").render(
        worlds=[{"id": 1, "name": "w"}], jobs=[], total=0, user=None, csrf_token="x",
        world_names={}, refresh=False, error=None, external_programs=["mine"],
        default_time_limit=7200.0,
    )  # fmt: skip
    for e in registry.entries():
        if e.replay_only:  # replays recorded logs (mapqual slam), cannot drive a run
            assert f'<option value="{e.name}">' not in html
        elif e.name == "external":  # one choice per program an administrator registered
            assert '<option value="external">' not in html
            assert '<option value="external:mine">' in html
        else:  # rbpf comes selected, the form's default
            chosen = " selected" if e.name == "rbpf" else ""
            assert f'<option value="{e.name}"{chosen}>{e.description}</option>' in html
    assert '<option value="plugin">a plugin SLAM</option>' in html


def test_the_api_schema_lists_the_registry_when_it_is_made(scratch_registry, tmp_path):
    from backend.core.config import Settings
    from mapqual.app import create_app

    registry.register("plugin", lambda laser, p, rng: None, "a plugin SLAM")
    settings = Settings(DATABASE_URL=f"sqlite:///{tmp_path / 'x.db'}", MAPQUAL_AUTH="on")
    job_in = create_app(settings).openapi()["components"]["schemas"]["JobIn"]["properties"]
    assert job_in["slam"]["anyOf"][0]["enum"] == [*registry.names()]
    assert job_in["params"]["properties"]["algorithm"]["enum"][-1] == "plugin"
    assert job_in["params"]["description"].startswith("Overrides by section")
