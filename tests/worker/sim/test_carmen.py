"""CARMEN logs: the lines we write, reading them back, classic FLASER logs, malformed input."""

from __future__ import annotations

import gzip
import io
import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.sim.carmen import CarmenWriter, read_laser_log
from worker.sim.laser import LaserSpec


def write_log(path, n_ticks=5, laser=None):
    laser = laser or LaserSpec()
    rng = np.random.default_rng(4)
    poses_gt = np.column_stack(
        [np.linspace(1, 2, n_ticks), np.linspace(3, 2, n_ticks), np.linspace(-3.1, 3.1, n_ticks)]
    )
    poses_odom = poses_gt + 0.01
    scans = rng.uniform(0.1, 30.0, (n_ticks, laser.n_beams))
    scans[:, 0] = laser.range_max
    with open(path, "w", newline="\n") as fh:
        w = CarmenWriter(fh, laser, comment="test log")
        for k in range(n_ticks):
            w.write_tick(0.1 * k, poses_gt[k], poses_odom[k], 0.5, -0.1, scans[k])
    return poses_gt, poses_odom, scans


def test_written_lines_have_the_carmen_field_layout(tmp_path):
    path = tmp_path / "sim.log"
    gt, odom, scans = write_log(path, n_ticks=2)
    lines = [ln.split() for ln in path.read_text().splitlines() if not ln.startswith("#")]
    assert [ln[0] for ln in lines] == ["ODOM", "ROBOTLASER1", "TRUEPOS"] * 2
    odom_line, laser_line, true_line = lines[3:6]
    # ODOM x y theta tv rv accel timestamp hostname logger_timestamp
    assert len(odom_line) == 10
    assert float(odom_line[1]) == pytest.approx(odom[1, 0], abs=1e-6)
    assert float(odom_line[7]) == pytest.approx(0.1) and odom_line[8] == "mapqual"
    # ROBOTLASER1: type, start, fov, res, max, accuracy, remission mode, n, ranges, n_rem,
    # laser pose, robot pose, tv, rv, forward, side, turn axis, timestamp, host, logger ts
    assert len(laser_line) == 1 + 8 + 541 + 1 + 6 + 5 + 3
    assert float(laser_line[2]) == pytest.approx(-3 * math.pi / 4, abs=1e-8)
    assert float(laser_line[3]) == pytest.approx(3 * math.pi / 2, abs=1e-8)
    assert float(laser_line[4]) == pytest.approx(math.pi / 360, abs=1e-9)
    assert float(laser_line[5]) == 30.0 and int(laser_line[8]) == 541
    np.testing.assert_allclose(np.array(laser_line[9:550], float), scans[1], atol=5e-4)
    assert int(laser_line[550]) == 0
    robot_pose = np.array(laser_line[554:557], float)
    np.testing.assert_allclose(robot_pose, odom[1], atol=1e-6)  # odometry pose as robot pose
    assert float(laser_line[562]) == pytest.approx(0.1)
    # TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta timestamp host logger_ts
    assert len(true_line) == 10
    np.testing.assert_allclose(np.array(true_line[1:4], float), gt[1], atol=1e-6)
    np.testing.assert_allclose(np.array(true_line[4:7], float), odom[1], atol=1e-6)


@pytest.mark.parametrize("gz", [False, True])
def test_round_trip(tmp_path, gz):
    path = tmp_path / "sim.log"
    gt, odom, scans = write_log(path)
    if gz:
        gz_path = tmp_path / "sim.log.gz"
        gz_path.write_bytes(gzip.compress(path.read_bytes()))
        path = gz_path
    log = read_laser_log(path)
    np.testing.assert_allclose(log.t, 0.1 * np.arange(5), atol=1e-9)
    assert log.ranges.dtype == np.float32 and log.ranges.shape == (5, 541)
    np.testing.assert_allclose(log.ranges, scans, atol=6e-4)
    np.testing.assert_allclose(log.pose_odom, odom, atol=1e-6)
    np.testing.assert_allclose(log.pose_gt, gt, atol=1e-6)
    np.testing.assert_allclose(log.t_gt, log.t)
    np.testing.assert_allclose(log.odom, odom, atol=1e-6)
    spec = log.laser
    assert spec.n_beams == 541 and spec.range_max == 30.0
    np.testing.assert_allclose(spec.angles, LaserSpec().angles, atol=1e-8)


def test_classic_flaser_log(tmp_path):
    # Intel/Freiburg style: PARAM lines, ODOM and FLASER with 180 beams, no TRUEPOS.
    ranges = " ".join(["2.50"] * 180)
    text = (
        "# CARMEN Logfile\n"
        "PARAM robot_front_laser_max 81.9 nohost 0\n"
        "ODOM 0.0 0.0 0.0 0.0 0.0 0.0 100.0 nohost 0.0\n"
        f"FLASER 180 {ranges} 1.0 2.0 0.5 1.1 2.1 0.6 100.05 nohost 0.1\n"
        "ODOM 0.1 0.0 0.0 0.2 0.0 0.0 100.1 nohost 0.2\n"
        f"FLASER 180 {ranges} 1.2 2.0 0.5 1.3 2.1 0.7 100.15 nohost 0.3\n"
    )
    path = tmp_path / "intel.log"
    path.write_text(text)
    log = read_laser_log(path)
    assert log.ranges.shape == (2, 180)
    np.testing.assert_allclose(log.t, [100.05, 100.15])
    np.testing.assert_allclose(log.pose_odom, [[1.1, 2.1, 0.6], [1.3, 2.1, 0.7]])
    assert log.pose_gt is None and log.t_gt is None
    np.testing.assert_allclose(log.t_odom, [100.0, 100.1])
    # 180 beams over 180 degrees from -90 degrees, 1 degree apart.
    assert log.laser.angle_min == pytest.approx(-math.pi / 2)
    assert log.laser.angle_increment == pytest.approx(math.pi / 180)


def test_pose_only_flaser_lines_are_not_scans(tmp_path):
    # The thesis wrote estimated poses as FLASER lines with zero readings.
    path = tmp_path / "est.log"
    path.write_text("FLASER 0 0.0 0.0 0.0 1.5 2.5 0.25 12.0\n")
    with pytest.raises(InputError, match="no ROBOTLASER1, FLASER or RAWLASER1 scans"):
        read_laser_log(path)


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("ROBOTLASER1 3 -2.3 4.7 0.0087 30.0 0.01 0 5 1 2 3\n", "fields"),
        ("ODOM 1.0 2.0 abc 0 0 0 1.0 host 1.0\n", "expected a number, got 'abc'"),
        ("TRUEPOS 1 2 3\n", "TRUEPOS line has 4 fields"),
        ("FLASER x 1 2 3\n", "num_readings must be an integer"),
    ],
)
def test_malformed_lines_name_file_and_line(tmp_path, line, message):
    path = tmp_path / "bad.log"
    good = io.StringIO()
    CarmenWriter(good, LaserSpec(n_beams=3, angle_min=-0.1, angle_increment=0.1)).write_tick(
        0.0, [0, 0, 0], [0, 0, 0], 0.0, 0.0, np.array([1.0, 2.0, 3.0])
    )
    text = good.getvalue()
    n_before = text.count("\n")
    path.write_text(text + line)
    with pytest.raises(InputError, match=message) as info:
        read_laser_log(path)
    assert info.value.line == n_before + 1
    assert str(path) in str(info.value)


def test_a_log_without_scans_is_an_input_error(tmp_path):
    path = tmp_path / "empty.log"
    path.write_text("# nothing\nODOM 0 0 0 0 0 0 1.0 h 1.0\n")
    with pytest.raises(InputError, match="no ROBOTLASER1, FLASER or RAWLASER1"):
        read_laser_log(path)
    with pytest.raises(InputError, match="no such file"):
        read_laser_log(tmp_path / "missing.log")
