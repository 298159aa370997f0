"""Strict parameter loading: defaults kept, types checked, unknown keys named."""

from __future__ import annotations

import dataclasses
import json
from typing import Literal

import pytest

from worker.errors import InputError
from worker.param_io import from_dict, load_params_file, to_dict


@dataclasses.dataclass(frozen=True)
class Inner:
    particles: int = 40
    sigma: float = 0.05  # [m]
    kind: Literal["rbpf", "odometry"] = "rbpf"

    def __post_init__(self):
        if self.particles < 1:
            raise ValueError("particles must be >= 1")


@dataclasses.dataclass(frozen=True)
class Outer:
    inner: Inner = dataclasses.field(default_factory=Inner)
    error: tuple[float, float, float] = (0.01, 0.01, 0.02)
    limit: float | None = None
    name: str = "x"
    flag: bool = False


def test_defaults_are_kept_and_ints_widen_to_floats():
    p = from_dict(Outer, {"inner": {"sigma": 1}, "limit": 3})
    assert p == Outer(inner=Inner(sigma=1.0), limit=3.0)
    assert isinstance(p.inner.sigma, float) and isinstance(p.limit, float)


def test_round_trip_through_json():
    p = Outer(inner=Inner(particles=7, kind="odometry"), error=(0.1, 0.2, 0.3), limit=None)
    assert from_dict(Outer, json.loads(json.dumps(to_dict(p)))) == p


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"inner": {"particle": 3}}, "unknown parameter inner.particle"),
        ({"inner": {"particles": 2.5}}, "inner.particles must be an integer"),
        ({"inner": {"particles": True}}, "inner.particles must be an integer"),
        ({"inner": {"kind": "ekf"}}, "inner.kind must be one of 'rbpf', 'odometry'"),
        ({"inner": {"particles": 0}}, "particles must be >= 1"),
        ({"error": [1, 2]}, "error must have 3 elements"),
        ({"error": "abc"}, "error must be a list"),
        ({"limit": "soon"}, "limit must be a number"),
        ({"limit": float("nan")}, "limit must be a finite number"),
        ({"flag": 1}, "flag must be true or false"),
        ({"inner": 5}, "inner must be a mapping"),
    ],
)
def test_bad_values_name_the_key(data, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        from_dict(Outer, data)


def test_params_file_yaml_and_json(tmp_path):
    y = tmp_path / "p.yaml"
    y.write_text("slam:\n  particles: 30\n")
    j = tmp_path / "p.json"
    j.write_text('{"slam": {"particles": 30}}')
    assert load_params_file(y) == load_params_file(j) == {"slam": {"particles": 30}}


def test_params_file_errors_name_file_and_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("slam:\n  particles: [1, 2\n")
    with pytest.raises(InputError, match=r"bad.yaml:\d+: not valid JSON/YAML"):
        load_params_file(bad)
    with pytest.raises(InputError, match="cannot read parameter file"):
        load_params_file(tmp_path / "missing.yaml")
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n- 2\n")
    with pytest.raises(InputError, match="mapping of sections"):
        load_params_file(lst)
