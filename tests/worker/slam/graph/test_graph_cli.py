"""graph everywhere rbpf is: `mapqual slam --algorithm graph`, a closed-loop `mapqual run
--slam graph` and `mapqual batch --slam graph,odometry` on a small world, with the graph
settings stored with the run (and rbpf runs' stored parameters left as they were)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from worker.errors import InputError
from worker.param_io import to_dict
from worker.run_params import RunParams
from worker.slam.graph.params import GraphSlamParams


def _rooms(folder: Path) -> Path:
    """10 x 6 m: two rooms joined by a 1 m door (as tests/cli's worlds)."""
    img = np.full((120, 200), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:, 100] = 0
    img[50:70, 100] = 255
    Image.fromarray(img).save(folder / "rooms.png")
    (folder / "rooms.yaml").write_text("image: rooms.png\nresolution: 0.05\n")
    return folder / "rooms.yaml"


def _mapqual(cwd: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = {**os.environ, "DATABASE_URL": f"sqlite:///{cwd / 'm.db'}", "COLUMNS": "200"}
    return subprocess.run(
        [sys.executable, "-m", "mapqual", *args], capture_output=True, text=True,
        env=env, cwd=cwd, timeout=timeout,
    )  # fmt: skip


def test_rbpf_params_json_has_no_graph_key_and_graph_runs_store_theirs():
    assert "graph" not in RunParams().to_json()["slam"]
    graph = RunParams(algorithm="graph").to_json()
    assert graph["slam"]["graph"] == to_dict(GraphSlamParams())
    assert RunParams.from_json(graph) == RunParams(algorithm="graph")


@pytest.mark.parametrize(
    ("graph", "needle"),
    [
        ({"minimum_travel_distance": -1.0}, "minimum_travel_distance must be a positive"),
        ({"loop_ambiguity_ratio": 1.5}, "loop_ambiguity_ratio must be in [0, 1]"),
        ({"scan_buffer_size": 0}, "scan_buffer_size must be in [1, 1000]"),
        ({"no_such_key": 1}, "unknown parameter slam.graph.no_such_key"),
    ],
)
def test_bad_graph_parameters_are_one_line_errors(graph, needle):
    with pytest.raises(InputError, match=re.escape(needle)):
        RunParams.from_json({"algorithm": "graph", "slam": {"graph": graph}})


def test_bad_graph_parameter_file_exits_2(tmp_path):
    world = _rooms(tmp_path)
    (tmp_path / "p.yaml").write_text("slam:\n  graph:\n    huber_delta: 0\n")
    r = _mapqual(tmp_path, "run", str(world), "--slam", "graph", "--params", "p.yaml")
    assert r.returncode == 2
    assert "huber_delta must be a positive number" in r.stderr
    assert "Traceback" not in r.stderr


def test_closed_loop_run_with_graph_completes(tmp_path):
    world = _rooms(tmp_path)
    r = _mapqual(
        tmp_path, "run", str(world), "--slam", "graph", "--seed", "2", "--time-limit", "120",
        "--json", "-o", "report",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["algorithm"] == "graph"
    assert summary["params"]["slam"]["graph"]["minimum_travel_distance"] == 0.5
    assert summary["relations"]["B"]["translation"]["n"] > 0
    assert summary["relations"]["B"]["translation"]["mean"] < 0.2
    # the final map carries graph's end-point counts: the map score takes its walls from them
    assert summary["map_score"]["walls"] == "density"
    assert (tmp_path / "report" / "summary.json").exists()


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("sim")
    world = _rooms(tmp)
    r = _mapqual(tmp, "simulate", str(world), "--duration", "40", "-o", "sim")
    assert r.returncode == 0, r.stderr
    return tmp / "sim" / "sim.log"


def test_offline_slam_with_graph_writes_map_and_params(log, tmp_path):
    r = _mapqual(tmp_path, "slam", str(log), "--algorithm", "graph", "-o", "out", "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["algorithm"] == "graph" and summary["updates"] > 5
    assert summary["params"]["graph"]["loop_search_maximum_distance"] == 3.0
    for name in ("map.pgm", "map.yaml", "map.png", "trajectory.tum", "slam.json"):
        assert (tmp_path / "out" / name).exists()


def test_batch_runs_graph_beside_odometry(tmp_path):
    worlds = tmp_path / "worlds"
    worlds.mkdir()
    _rooms(worlds)
    r = _mapqual(
        tmp_path, "batch", str(worlds), "--seeds", "1", "--slam", "graph,odometry",
        "--time-limit", "40", "--workers", "1", "-o", "out",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    records = [json.loads(p.read_text()) for p in (tmp_path / "out").glob("runs/*/record.json")]
    assert sorted(rec["slam"] for rec in records) == ["graph", "odometry"]
    assert all(rec["status"] == "done" for rec in records)
