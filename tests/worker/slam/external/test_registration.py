"""Registering external algorithms: the `slam.external` params section (stored with the run)
and in-process plugins from the `mapqual.slam` entry points group."""

from __future__ import annotations

import sys
from importlib.metadata import EntryPoint, entry_points

import pytest

from worker.errors import InputError
from worker.run_params import RunParams
from worker.sim.laser import LaserSpec
from worker.slam import registry
from worker.slam.external.params import ExternalSlamParams
from worker.slam.registry import make_slam


@pytest.fixture
def scratch_registry(monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))


def test_the_external_section_round_trips_and_is_absent_for_other_algorithms():
    data = {
        "algorithm": "external",
        "slam": {"external": {"name": "mine", "command": ["prog", "-v"], "step_timeout_s": 2.5}},
    }
    params = RunParams.from_json(data)
    assert params.slam.external == ExternalSlamParams("mine", ("prog", "-v"), step_timeout_s=2.5)
    stored = params.to_json()
    assert stored["slam"]["external"] == {
        "name": "mine", "command": ["prog", "-v"], "start_timeout_s": 30.0,
        "step_timeout_s": 2.5, "close_timeout_s": 2.0,
    }  # fmt: skip
    assert RunParams.from_json(stored) == params
    assert "external" not in RunParams().to_json()["slam"]  # other runs keep their JSON
    # one --params file for `--slam rbpf,external`: the other algorithms drop the section
    rbpf = RunParams.from_json({**data, "algorithm": "rbpf"})
    assert rbpf.slam.external is None and rbpf == RunParams()


@pytest.mark.parametrize(
    ("data", "needle"),
    [
        ({"algorithm": "external"}, "algorithm 'external' needs slam.external"),
        (
            {"algorithm": "external", "slam": {"external": {"name": "", "command": ["p"]}}},
            "slam.external.name '' must be an identifier",
        ),
        (
            {"algorithm": "external", "slam": {"external": {"name": "a b", "command": ["p"]}}},
            "must be an identifier",
        ),
        (
            {"algorithm": "external", "slam": {"external": {"name": "x", "command": "p -v"}}},
            "slam.external.command must be a list",
        ),
        (
            {"algorithm": "external", "slam": {"external": {"name": "x", "step_timeout_s": 0}}},
            "step_timeout_s must be a positive number",
        ),
    ],
)
def test_bad_external_sections_are_input_errors(data, needle):
    with pytest.raises(InputError, match=needle):
        RunParams.from_json(data)


def test_an_external_run_without_a_command_is_refused_when_made():
    params = RunParams.from_json({"algorithm": "external", "slam": {"external": {"name": "x"}}})
    with pytest.raises(InputError, match="needs slam.external.command"):
        make_slam("external", LaserSpec(), params.slam)


def test_entry_points_register_plugins_lazily(scratch_registry, tmp_path, monkeypatch):
    pkg = tmp_path / "site"
    (pkg / "h20_plugin").mkdir(parents=True)
    (pkg / "h20_plugin" / "__init__.py").write_text(
        "from worker.slam.odometry import OdometrySlam\n"
        "LOADED = []\n"
        "def make(laser, params, rng):\n"
        "    LOADED.append(1)\n"
        "    return OdometrySlam(laser, params)\n"
    )
    dist = pkg / "h20_plugin-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: h20-plugin\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(
        "[mapqual.slam]\nh20plug = h20_plugin:make\nbad name = h20_plugin:make\n"
        "rbpf = h20_plugin:make\n"
    )
    monkeypatch.syspath_prepend(str(pkg))
    assert {e.name for e in entry_points(group="mapqual.slam")} >= {"h20plug", "rbpf"}
    assert registry.load_plugins() == ["h20plug"]  # the taken and the bad name are skipped
    assert "h20_plugin" not in sys.modules  # registered without being imported
    assert registry.load_plugins() == []  # loading again adds nothing
    assert RunParams.from_json({"algorithm": "h20plug"}).algorithm == "h20plug"
    slam = make_slam("h20plug", LaserSpec())
    assert type(slam).__name__ == "OdometrySlam" and sys.modules["h20_plugin"].LOADED == [1]
    assert registry.get("rbpf").description == "rbpf (GMapping)"  # not replaced


def test_an_entry_point_object_is_the_factory(scratch_registry):
    ep = EntryPoint("h20x", "worker.slam.registry:_odometry", "mapqual.slam")
    assert registry.load_plugins((ep,)) == ["h20x"]
    assert type(make_slam("h20x", LaserSpec())).__name__ == "OdometrySlam"
