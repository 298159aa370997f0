"""`mapqual simulate`: files written, same seed same bytes, path driving, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from worker.sim.carmen import read_laser_log


@pytest.fixture
def room_yaml(tmp_path) -> Path:
    img = np.zeros((120, 200), dtype=np.uint8)
    img[1:-1, 1:-1] = 255  # 10 m x 6 m at 0.05 m/px
    img[50:70, 90:110] = 0  # a 1 m pillar
    Image.fromarray(img).save(tmp_path / "room.pgm")
    path = tmp_path / "room.yaml"
    path.write_text("image: room.pgm\nresolution: 0.05\norigin: [-1.0, -2.0, 0.0]\n")
    return path


def test_simulate_writes_a_readable_log(run, room_yaml, tmp_path):
    out = tmp_path / "out"
    code, stdout, err = run(
        "simulate",
        room_yaml,
        "--seed",
        "3",
        "--duration",
        "15",
        "--laser-noise",
        "0.1",
        "-o",
        out,
        "--plot",
    )
    assert code == 0, err
    for f in ("sim.log", "gt.tum", "odom.tum", "sim.json", "sim.png"):
        assert (out / f).is_file(), f
    assert "151 scans over 15.0 s simulated" in stdout
    log = read_laser_log(out / "sim.log")
    assert log.ranges.shape == (151, 541) and log.pose_gt.shape == (151, 3)
    # All poses lie inside the room in the YAML's frame (origin (-1, -2)).
    assert np.all(log.pose_gt[:, 0] > -1.0 + 0.2) and np.all(log.pose_gt[:, 0] < 9.0 - 0.2)
    assert np.all(log.pose_gt[:, 1] > -2.0 + 0.2) and np.all(log.pose_gt[:, 1] < 4.0 - 0.2)
    summary = json.loads((out / "sim.json").read_text())
    assert summary["seed"] == 3 and summary["params"]["laser_noise_sigma"] == 0.1


def test_same_seed_identical_log_bytes(run, room_yaml, tmp_path):
    for name in ("a", "b"):
        code, _, err = run(
            "simulate",
            room_yaml,
            "--seed",
            "9",
            "--duration",
            "10",
            "--odom-model",
            "gaussian",
            "-o",
            tmp_path / name,
        )
        assert code == 0, err
    assert (tmp_path / "a" / "sim.log").read_bytes() == (tmp_path / "b" / "sim.log").read_bytes()


def test_simulate_along_a_path(run, room_yaml, tmp_path):
    path = tmp_path / "path.txt"
    path.write_text("1.0 -1.0\n7.0 -1.0\n7.0 3.0\n")
    code, stdout, err = run(
        "simulate",
        room_yaml,
        "--drive",
        "path",
        "--path",
        path,
        "--duration",
        "120",
        "-o",
        tmp_path / "out",
        "--json",
    )
    assert code == 0, err
    result = json.loads(stdout)
    assert result["path_completed"] is True and result["collisions"] == []


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--drive", "path"], "--drive path needs --path FILE"),
        (["--laser-noise", "-1"], "laser noise sigma must be >= 0"),
        (["--duration", "0"], "duration must be > 0"),
    ],
)
def test_simulate_errors_are_one_line_with_exit_2(run, room_yaml, tmp_path, args, message):
    code, _, err = run("simulate", room_yaml, "-o", tmp_path / "out", *args)
    assert code == 2 and message in err and err.count("\n") == 1


def test_a_waypoint_inside_a_wall_is_rejected(run, room_yaml, tmp_path):
    path = tmp_path / "path.txt"
    path.write_text("1.0 -1.0\n# the pillar:\n4.0 1.0\n")
    code, _, err = run(
        "simulate", room_yaml, "--drive", "path", "--path", path, "-o", tmp_path / "out"
    )
    assert code == 2 and "waypoint 2 (4, 1) is not on a free cell" in err


def test_a_given_start_pose(run, room_yaml, tmp_path):
    code, _, err = run(
        "simulate",
        room_yaml,
        "--start",
        "1.5",
        "-1.0",
        "1.0",
        "--duration",
        "1",
        "-o",
        tmp_path / "out",
    )
    assert code == 0, err
    log = read_laser_log(tmp_path / "out" / "sim.log")
    np.testing.assert_allclose(log.pose_gt[0], [1.5, -1.0, 1.0], atol=1e-6)
    code, _, err = run("simulate", room_yaml, "--start", "4.0", "1.0", "0", "-o", tmp_path / "out")
    assert code == 2 and "not on a free cell" in err and err.count("\n") == 1
    code, _, err = run(
        "simulate", room_yaml, "--start", "-0.85", "-1.0", "0", "-o", tmp_path / "out"
    )
    assert code == 2 and "overlaps an obstacle" in err and err.count("\n") == 1
