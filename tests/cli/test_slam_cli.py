"""`mapqual slam`: the files it writes from a simulated log, determinism, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from worker.evaluate.trajio import read_trajectory
from worker.sim.carmen import read_laser_log
from worker.sim.run import run_simulation
from worker.world.world import World


@pytest.fixture(scope="module")
def sim_log(tmp_path_factory) -> Path:
    occ = np.zeros((120, 200), dtype=bool)  # 10 m x 6 m room with a pillar
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    occ[50:70, 90:110] = True
    world = World.from_array(occ, 0.05, origin=(-1.0, -2.0), start_pose=(1.0, 0.0, 0.0))
    out = tmp_path_factory.mktemp("sim")
    run_simulation(world, out, seed=3, duration_s=25.0)
    return out / "sim.log"


def test_slam_writes_map_and_trajectory(run, sim_log, tmp_path):
    log = read_laser_log(sim_log)
    out = tmp_path / "rbpf"
    code, stdout, err = run("slam", sim_log, "-o", out, "--particles", 5, "--seed", 1, "--json")
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["scans"] == len(log.t) and summary["params"]["particles"] == 5
    assert summary["updates"] >= 2
    for name in ("map.pgm", "map.yaml", "map.png", "trajectory.log", "trajectory.tum"):
        assert (out / name).is_file()
    meta = yaml.safe_load((out / "map.yaml").read_text())
    assert meta["image"] == "map.pgm" and meta["resolution"] == 0.05
    img = np.array(Image.open(out / "map.pgm"))
    assert set(np.unique(img)) <= {0, 205, 254} and (img == 0).any() and (img == 254).any()
    # the thesis listener format: one FLASER line per laser timestamp
    lines = (out / "trajectory.log").read_text().splitlines()
    assert len(lines) == len(log.t)
    assert lines[0].startswith("FLASER 0 0.0 0.0 0.0 ")
    carmen = read_trajectory(out / "trajectory.log")
    tum = read_trajectory(out / "trajectory.tum")
    assert np.allclose(carmen.t, log.t) and np.allclose(tum.poses, carmen.poses, atol=1e-6)
    # the map frame is the odometry frame of the first scan
    assert np.allclose(carmen.poses[0], log.pose_odom[0])
    # the estimate stays near the ground truth in this small room
    gt = log.pose_gt[np.searchsorted(log.t_gt, log.t)]
    assert np.hypot(*(carmen.poses[:, :2] - gt[:, :2]).T).max() < 0.3
    # the trajectory is the best particle's path; online.tum each scan's estimate at the time:
    # the same times, and the same pose at the last scan (the best particle's, then)
    online = read_trajectory(out / "online.tum")
    assert np.array_equal(online.t, tum.t)
    assert np.allclose(online.poses[-1], tum.poses[-1], atol=1e-6)
    assert np.hypot(*(online.poses[:, :2] - gt[:, :2]).T).max() < 0.3


def test_same_seed_same_bytes(run, sim_log, tmp_path):
    outs = []
    for k in range(2):
        code, _, err = run("slam", sim_log, "-o", tmp_path / str(k), "--particles", 4)
        assert code == 0, err
        outs.append(tmp_path / str(k))
    for name in ("map.pgm", "trajectory.log"):
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes()


def test_odometry_algorithm_and_params_file(run, sim_log, tmp_path):
    params = tmp_path / "p.yaml"
    params.write_text("slam:\n  linear_update: 0.5\n  delta: 0.1\n")
    code, stdout, err = run(
        "slam",
        sim_log,
        "-o",
        tmp_path / "o",
        "--algorithm",
        "odometry",
        "--params",
        params,
        "--json",
    )
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["params"]["linear_update"] == 0.5 and summary["params"]["delta"] == 0.1
    assert yaml.safe_load((tmp_path / "o" / "map.yaml").read_text())["resolution"] == 0.1
    # odometry: the estimate is the log's odometry
    est = read_trajectory(tmp_path / "o" / "trajectory.log")
    assert np.allclose(est.poses, read_laser_log(sim_log).pose_odom, atol=1e-6)
    assert not (tmp_path / "o" / "online.tum").exists()  # no final trajectory apart from it


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.log"], "no such file"),
        (["LOG", "--particles", "0"], "particles must be >= 1"),
        (["LOG", "--delta", "-1"], "delta must be a positive"),
    ],
)
def test_bad_input_is_one_line_exit_2(run, sim_log, tmp_path, args, message):
    args = [sim_log if a == "LOG" else tmp_path / a if a.endswith(".log") else a for a in args]
    code, _, err = run("slam", *args, "-o", tmp_path / "x")
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1


def test_classic_flaser_log_with_180_beams(run, tmp_path):
    """A Freiburg-style log: FLASER lines of 181 beams over 180 degrees carry the odometry."""
    from tests.worker.slam.helpers import box_scan

    angles = -np.pi / 2 + np.pi / 180 * np.arange(181)
    lines = []
    for k in range(60):  # 0.1 m per scan along the room, weaving a little
        x, y, th = 1.0 + 0.1 * k, 2.0 + 0.3 * np.sin(0.1 * k), 0.1 * np.cos(0.1 * k)
        ranges = box_scan((x, y, th), angles, (0.0, 0.0, 9.0, 4.0), range_max=80.0)
        fields = [f"{r:.3f}" for r in ranges] + [f"{v:.6f}" for v in (x, y, th, x, y, th)]
        lines.append(f"FLASER 181 {' '.join(fields)} {0.1 * k:.3f} host {0.1 * k:.3f}")
    log = tmp_path / "classic.log"
    log.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    code, stdout, err = run("slam", log, "-o", out, "--particles", 5, "--json")
    assert code == 0, err
    assert json.loads(stdout)["scans"] == 60
    est = read_trajectory(out / "trajectory.log")
    assert len(est.t) == 60
    # exact odometry in a closed-form room: the estimate stays on it
    x = 1.0 + 0.1 * np.arange(60)
    assert np.abs(est.poses[:, 0] - x).max() < 0.05
    img = np.array(Image.open(out / "map.pgm"))
    assert (img == 0).sum() > 100  # the room's walls are mapped


def test_third_party_algorithm_without_its_package_is_one_line_exit_2(
    run, sim_log, tmp_path, monkeypatch
):
    # MRPT's programs looked for on a PATH that has none of them: refused before any work
    monkeypatch.setenv("PATH", str(tmp_path))
    code, _, err = run("slam", sim_log, "-o", tmp_path / "x", "--algorithm", "mrpt_rbpf")
    assert code == 2
    assert "apt-get install mrpt-apps" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x" / "trajectory.tum").exists()
