"""Standalone simulation runs: files written, determinism, path runs, validation."""

from __future__ import annotations

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.trajio import read_trajectory
from worker.sim.carmen import read_laser_log
from worker.sim.params import SimParams
from worker.sim.run import run_simulation
from worker.world import World

RES = 0.05


@pytest.fixture(scope="module")
def world() -> World:
    occ = np.ones((120, 200), dtype=bool)
    occ[1:-1, 1:-1] = False  # 10 m x 6 m room
    occ[40:80, 90:110] = True  # a 1 m x 2 m pillar in the middle
    return World.from_array(occ, RES, start_pose=(2.0, 3.0, 0.0), name="pillar")


def test_same_seed_same_bytes_and_another_seed_differs(world, tmp_path):
    params = SimParams(laser_noise_sigma=0.1)
    for name, seed in (("a", 7), ("b", 7), ("c", 8)):
        run_simulation(world, tmp_path / name, seed=seed, duration_s=20.0, params=params)
    for f in ("sim.log", "gt.tum", "odom.tum", "sim.json"):
        assert (tmp_path / "a" / f).read_bytes() == (tmp_path / "b" / f).read_bytes(), f
    assert (tmp_path / "a" / "sim.log").read_bytes() != (tmp_path / "c" / "sim.log").read_bytes()


def test_log_and_tum_files_agree(world, tmp_path):
    result = run_simulation(world, tmp_path, seed=1, duration_s=30.0)
    assert result.n_ticks == 301 and result.sim_time_s == pytest.approx(30.0)
    log = read_laser_log(tmp_path / "sim.log")
    np.testing.assert_allclose(log.t, 0.1 * np.arange(301), atol=1e-9)
    assert log.ranges.shape == (301, 541)
    gt = read_trajectory(tmp_path / "gt.tum")
    odom = read_trajectory(tmp_path / "odom.tum")
    np.testing.assert_allclose(gt.t, log.t_gt, atol=1e-6)
    np.testing.assert_allclose(gt.poses, log.pose_gt, atol=2e-6)
    np.testing.assert_allclose(odom.poses, log.pose_odom, atol=2e-6)
    # The evaluator's own CARMEN reader finds the same ground truth and odometry in the log.
    gt_carmen = read_trajectory(tmp_path / "sim.log", message="TRUEPOS")
    np.testing.assert_allclose(gt_carmen.poses, gt.poses, atol=2e-6)
    laser_carmen = read_trajectory(tmp_path / "sim.log", message="ROBOTLASER1")
    np.testing.assert_allclose(laser_carmen.poses, odom.poses, atol=2e-6)
    # The wanderer moved, and the log's first pose is the world's start pose.
    np.testing.assert_allclose(log.pose_gt[0], world.start_pose, atol=1e-6)
    assert result.distance_m > 3.0
    steps = np.diff(log.pose_gt[:, :2], axis=0)
    assert result.distance_m == pytest.approx(np.hypot(*steps.T).sum(), abs=1e-3)


def test_path_run_ends_when_the_path_is_done(world, tmp_path):
    points = np.array([[3.0, 1.0], [8.0, 1.0], [8.5, 5.0]])
    result = run_simulation(
        world, tmp_path, seed=0, duration_s=300.0, drive="path", waypoints=points
    )
    assert result.path_completed and not result.collisions
    assert result.sim_time_s < 100.0
    gt = read_trajectory(tmp_path / "gt.tum")
    assert np.hypot(*(gt.poses[-1, :2] - points[-1])) <= 0.2 + 1e-9


def test_bad_runs(world, tmp_path):
    with pytest.raises(InputError, match="not on a free cell"):
        run_simulation(world, tmp_path, drive="path", waypoints=np.array([[5.0, 3.0]]))
    with pytest.raises(InputError, match="needs waypoints"):
        run_simulation(world, tmp_path, drive="path")
    with pytest.raises(InputError, match="duration"):
        run_simulation(world, tmp_path, duration_s=0.0)
