"""The SLAM problem made from a corrected log: drifting odometry, ground truth, the files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.trajio import read_trajectory
from worker.sim.carmen import LaserLog, read_laser_log
from worker.sim.drift import (
    DriftParams,
    drift_odometry,
    drifting_problem,
    log_slice,
    write_problem_log,
)
from worker.sim.laser import LaserSpec


def square_path(n: int = 9) -> np.ndarray:
    """A 1 m square walked in 0.5 m steps, turning left at the corners."""
    poses = [[0.0, 0.0, 0.0]]
    for k in range(1, n):
        x, y, th = poses[-1]
        if k % 2 == 0:
            th = (th + math.pi / 2 + math.pi) % (2 * math.pi) - math.pi
        poses.append([x + 0.5 * math.cos(th), y + 0.5 * math.sin(th), th])
    return np.array(poses)


def corrected_log(n: int = 9) -> LaserLog:
    pose = square_path(n)
    laser = LaserSpec(n_beams=4, angle_min=-math.pi / 2, angle_increment=math.pi / 3, range_max=50)
    ranges = np.tile(np.array([1.0, 2.0, 50.0, 3.0], dtype=np.float32), (n, 1))
    t = np.arange(n, dtype=float)
    empty = np.zeros((0, 3))
    return LaserLog(t, ranges, pose, laser, None, None, np.zeros(0), empty, "square.log", "FLASER")


def test_without_drift_the_odometry_is_the_truth():
    odom, scale = drift_odometry(square_path(), np.random.default_rng(1), DriftParams(0.0, 0.0))
    np.testing.assert_allclose(odom, square_path(), atol=1e-12)
    assert scale.tolist() == [1.0, 1.0, 1.0]


def test_a_scale_error_alone_stretches_every_step():
    # straight along x: each 0.5 m step becomes s_x * 0.5 m, by hand
    path = np.column_stack([0.5 * np.arange(5), np.zeros(5), np.zeros(5)])
    odom, scale = drift_odometry(path, np.random.default_rng(3), DriftParams(0.03, 0.0))
    np.testing.assert_allclose(odom[:, 0], scale[0] * 0.5 * np.arange(5), atol=1e-12)
    np.testing.assert_allclose(odom[:, 1:], 0.0, atol=1e-12)
    assert scale[0] != 1.0


def test_step_noise_is_relative_to_each_step():
    # a pure turn has no translation noise; its heading error is about 5 % of the turn
    path = np.column_stack([np.zeros(201), np.zeros(201), 0.01 * np.arange(201)])
    odom, _ = drift_odometry(path, np.random.default_rng(5), DriftParams(0.0, 0.05))
    np.testing.assert_allclose(odom[:, :2], 0.0, atol=1e-12)
    step_err = np.diff(odom[:, 2]) - 0.01
    assert 0.04 * 0.01 < step_err.std() < 0.06 * 0.01


def test_the_problem_is_seeded_and_keeps_the_scans():
    log = corrected_log()
    a, gt = drifting_problem(log, seed=7)
    b, _ = drifting_problem(log, seed=7)
    c, _ = drifting_problem(log, seed=8)
    np.testing.assert_array_equal(a.pose_odom, b.pose_odom)
    assert not np.array_equal(a.pose_odom, c.pose_odom)
    np.testing.assert_array_equal(a.ranges, log.ranges)
    np.testing.assert_array_equal(gt.poses, square_path())
    np.testing.assert_array_equal(a.pose_gt, square_path())
    np.testing.assert_array_equal(a.pose_odom[0], square_path()[0])  # starts at the truth
    assert np.abs(a.pose_odom[-1] - square_path()[-1]).max() > 1e-4  # and drifts away


def test_the_problem_log_reads_back(tmp_path):
    problem, gt = drifting_problem(corrected_log(), seed=2)
    path = tmp_path / "problem.log"
    write_problem_log(path, problem, comment="test")
    back = read_laser_log(path)
    assert back.message == "ROBOTLASER1"
    np.testing.assert_allclose(back.pose_odom, problem.pose_odom, atol=1e-6)
    np.testing.assert_allclose(back.pose_gt, gt.poses, atol=1e-6)
    np.testing.assert_allclose(back.ranges, problem.ranges, atol=5e-4)
    assert back.laser.range_max == 50.0 and back.laser.n_beams == 4
    assert read_trajectory(path, message="TRUEPOS").t.tolist() == gt.t.tolist()


def test_a_slice_and_bad_input():
    log = corrected_log()
    part = log_slice(log, 2, 5)
    np.testing.assert_array_equal(part.pose_odom, log.pose_odom[2:5])
    with pytest.raises(InputError, match="0 <= start < stop"):
        log_slice(log, 5, 5)
    with pytest.raises(InputError, match="scale_std must be in"):
        DriftParams(scale_std=-0.1)
    with pytest.raises(InputError, match="at least 2 scans"):
        drifting_problem(log_slice(log, 0, 1), seed=0)
