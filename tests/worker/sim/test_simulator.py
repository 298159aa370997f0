"""The simulator: laser noise, Stage odometry, collisions, limits and determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.sim.collision import footprint_collides
from worker.sim.params import SimParams
from worker.sim.simulator import Simulator
from worker.world import World

RES = 0.05


def room_world(width_m: float = 12.0, height_m: float = 6.0, start=None) -> World:
    w, h = round(width_m / RES), round(height_m / RES)
    occ = np.ones((h, w), dtype=bool)
    occ[1:-1, 1:-1] = False
    return World.from_array(occ, RES, start_pose=start, name="room")


def test_range_noise_has_the_requested_sigma():
    world = room_world(start=(6.0, 3.0, 0.0))
    sigma = 0.1
    noisy = Simulator(world, SimParams(laser_noise_sigma=sigma), np.random.default_rng(7))
    clean = Simulator(world, SimParams(), np.random.default_rng(7))
    err = np.concatenate([noisy.scan() - clean.scan() for _ in range(60)])
    # 60 x 541 samples: the sample std is within ~1 % of sigma; the mean is ~0.
    assert err.std() == pytest.approx(sigma, rel=0.03)
    assert abs(err.mean()) < 0.003


def test_the_noise_free_scan_is_what_a_clean_laser_reads_and_draws_nothing():
    # the audit's view (bench_safety): the noisy simulator's noise-free scan equals a
    # noise-free simulator's, and asking for it leaves the noise stream where it was, so a
    # run audited is the run unaudited
    world = room_world(start=(6.0, 3.0, 0.0))
    noisy = Simulator(world, SimParams(laser_noise_sigma=0.1), np.random.default_rng(7))
    twin = Simulator(world, SimParams(laser_noise_sigma=0.1), np.random.default_rng(7))
    clean = Simulator(world, SimParams(), np.random.default_rng(7))
    np.testing.assert_array_equal(noisy.scan_noise_free(), clean.scan())
    np.testing.assert_array_equal(noisy.scan(), twin.scan())


def test_beams_with_no_return_read_range_max_even_with_noise():
    occ = np.zeros((1400, 1400), dtype=bool)  # 70 m x 70 m open area: nothing within 30 m
    world = World.from_array(occ, RES, start_pose=(35.0, 35.0, 0.0))
    sim = Simulator(world, SimParams(laser_noise_sigma=0.3), np.random.default_rng(1))
    np.testing.assert_array_equal(sim.scan(), 30.0)


def drive(sim: Simulator, v: float, w: float, seconds: float) -> None:
    for _ in range(round(seconds / sim.params.dt)):
        sim.step(v, w)


def test_stage_odometry_reproduces_its_scale_factors():
    world = room_world(30.0, 6.0, start=(2.0, 3.0, 0.0))
    sim = Simulator(world, SimParams(), np.random.default_rng(3))
    ex, _, eth = sim.odom_error_factors
    assert abs(ex) <= 0.005 and abs(eth) <= 0.01  # uniform in [-E/2, E/2], E = (0.01, 0.01, 0.02)
    drive(sim, 0.8, 0.0, 25.0)
    travelled_gt = sim.pose_gt[0] - 2.0
    travelled_odom = sim.pose_odom[0] - 2.0
    assert travelled_gt > 15.0
    assert travelled_odom / travelled_gt == pytest.approx(1.0 + ex, abs=1e-9)
    # Turning in place: the odometry angle is the true angle scaled by (1 + e_theta).
    sim2 = Simulator(room_world(start=(6.0, 3.0, 0.0)), SimParams(), np.random.default_rng(3))
    turned = 0.0
    for _ in range(10):
        th_gt, th_odom = sim2.pose_gt[2], sim2.pose_odom[2]
        sim2.step(0.0, 0.5)
        turned += (sim2.pose_gt[2] - th_gt + math.pi) % (2 * math.pi) - math.pi
        d_odom = (sim2.pose_odom[2] - th_odom + math.pi) % (2 * math.pi) - math.pi
        assert d_odom == pytest.approx(
            ((sim2.pose_gt[2] - th_gt + math.pi) % (2 * math.pi) - math.pi) * (1.0 + eth), abs=1e-12
        )
    assert turned > 0.2


def test_stage_error_factors_are_uniform_in_half_e():
    world = room_world(start=(6.0, 3.0, 0.0))
    factors = np.array(
        [
            Simulator(world, SimParams(), np.random.default_rng(s)).odom_error_factors
            for s in range(400)
        ]
    )
    e = np.array([0.01, 0.01, 0.02])
    assert np.all(np.abs(factors) <= e / 2)
    # Uniform on [-E/2, E/2] has std E / sqrt(12).
    np.testing.assert_allclose(factors.std(axis=0), e / math.sqrt(12), rtol=0.12)


def test_gaussian_odometry_error_grows_as_the_model_says():
    world = room_world(30.0, 6.0, start=(2.0, 3.0, 0.0))
    sigma_xy = 0.05
    params = SimParams(odom_model="gaussian", odom_sigmas=(sigma_xy, 0.05, 0.02))
    finals = []
    for seed in range(120):
        sim = Simulator(world, params, np.random.default_rng(seed))
        x_gt = [sim.pose_gt[0]]
        for _ in range(60):
            sim.step(1.0, 0.0)
            x_gt.append(sim.pose_gt[0])
        finals.append(sim.pose_odom[0] - sim.pose_gt[0])
    # Straight drive: the x error is the sum of independent N(0, sigma_xy * dx_k) per step (the
    # heading error only moves y to first order), so its std is sigma_xy * sqrt(sum dx_k^2).
    dx = np.diff(x_gt)
    expected = sigma_xy * math.sqrt(float(np.sum(dx**2)))
    assert np.std(finals) == pytest.approx(expected, rel=0.2)


def test_a_drive_into_a_wall_is_a_collision_and_stops_the_robot():
    world = room_world(start=(6.0, 3.0, 0.0))  # inner wall face at x = 11.95
    sim = Simulator(world, SimParams(), np.random.default_rng(0))
    drive(sim, 1.0, 0.0, 10.0)
    assert sim.collided and len(sim.collisions) == 1
    hit = sim.collisions[0]
    # The footprint's front (x + 0.2) stops within one sub-step (half a cell) of the wall face.
    assert 11.95 - 0.2 - 0.5 * RES <= hit.x <= 11.95 - 0.2
    assert hit.y == pytest.approx(3.0)
    # Reached at 1 m/s after the ramp: (11.75 - 6.0) m takes ~6.1 s.
    assert 5.5 < hit.t < 6.6
    assert sim.velocity == (0.0, 0.0)
    assert sim.pose_gt[0] == pytest.approx(hit.x)
    # The robot can back away, and a second drive into the wall is a second collision.
    drive(sim, -0.5, 0.0, 2.0)
    assert not sim.in_contact and sim.pose_gt[0] < hit.x - 0.5
    drive(sim, 1.0, 0.0, 5.0)
    assert len(sim.collisions) == 2


def test_a_fast_robot_cannot_tunnel_through_a_one_pixel_wall():
    occ = np.ones((120, 240), dtype=bool)
    occ[1:-1, 1:-1] = False
    occ[:, 120] = True  # a 5 cm wall at x in [6.0, 6.05)
    world = World.from_array(occ, RES, start_pose=(3.0, 3.0, 0.0))
    params = SimParams(v_max=10.0, acc_lin=100.0)  # 1 m per step, 20 wall thicknesses
    sim = Simulator(world, params, np.random.default_rng(0))
    drive(sim, 10.0, 0.0, 2.0)
    assert sim.collided
    assert sim.pose_gt[0] < 6.0 - 0.2 + 1e-9


def test_speed_and_acceleration_limits():
    world = room_world(30.0, 6.0, start=(2.0, 3.0, 0.0))
    params = SimParams(v_max=0.8, acc_lin=1.0)
    sim = Simulator(world, params, np.random.default_rng(0))
    sim.step(5.0, 0.0)
    assert sim.velocity[0] == pytest.approx(0.1)  # acc_lin * dt
    drive(sim, 5.0, 0.0, 2.0)
    assert sim.velocity[0] == pytest.approx(0.8)
    sim.step(0.0, 100.0)
    assert sim.velocity[1] == pytest.approx(0.25)  # acc_ang 2.5 * dt
    assert sim.t == pytest.approx(2.2)


def test_footprint_collision_is_the_rotated_square():
    occ = np.zeros((40, 40), dtype=bool)
    occ[20, 30] = True  # obstacle cell x in [1.5, 1.55), y in [1.0, 1.05)
    half = 0.2
    # Axis-aligned square centred at y = 1.025: front face at x + 0.2.
    assert not footprint_collides(occ, RES, 0.0, 0.0, 1.29, 1.025, 0.0, half)
    assert footprint_collides(occ, RES, 0.0, 0.0, 1.31, 1.025, 0.0, half)
    # Rotated 45 degrees: the corner reaches 0.2 * sqrt(2) = 0.283 ahead.
    assert footprint_collides(occ, RES, 0.0, 0.0, 1.23, 1.025, math.pi / 4, half)
    assert not footprint_collides(occ, RES, 0.0, 0.0, 1.21, 1.025, math.pi / 4, half)


def test_a_start_pose_against_a_wall_is_rejected():
    world = room_world(start=(0.2, 3.0, 0.0))
    with pytest.raises(InputError, match="overlaps an obstacle"):
        Simulator(world, SimParams(), np.random.default_rng(0))


def test_a_non_finite_command_is_refused():
    sim = Simulator(room_world(start=(6.0, 3.0, 0.0)), SimParams(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="finite"):
        sim.step(float("nan"), 0.0)
    np.testing.assert_allclose(sim.pose_gt, [6.0, 3.0, 0.0])


def test_bad_parameters_are_input_errors():
    with pytest.raises(InputError, match="laser noise"):
        SimParams(laser_noise_sigma=-1.0)
    with pytest.raises(InputError, match="odom_model"):
        SimParams(odom_model="magic")


def test_same_seed_same_trajectory_and_scans():
    world = room_world(start=(6.0, 3.0, 0.0))
    params = SimParams(laser_noise_sigma=0.1, odom_model="gaussian")

    def run(seed):
        sim = Simulator(world, params, np.random.default_rng(seed))
        out = []
        for k in range(50):
            sim.step(0.5, 0.3 * math.sin(k / 5))
            out.append(np.concatenate([sim.pose_gt, sim.pose_odom, sim.scan()]))
        return np.array(out)

    np.testing.assert_array_equal(run(11), run(11))
    assert not np.array_equal(run(11), run(12))


def test_a_hand_built_world_without_clearance_still_simulates():
    import dataclasses

    world = dataclasses.replace(room_world(start=(6.0, 3.0, 0.0)), clearance=None)
    sim = Simulator(world, SimParams(), np.random.default_rng(0))
    ranges = sim.scan()
    assert ranges[270] == pytest.approx(11.95 - 6.0)  # straight ahead to the inner wall face


def test_footprint_collision_agrees_with_point_sampling(rng):
    # Any sampled point of the (rotated) footprint inside an occupied cell means a collision;
    # no sampled point inside, with the footprint shrunk by 1 mm still colliding, would mean a
    # false alarm larger than the sampling step.
    occ = rng.uniform(size=(60, 60)) < 0.007  # about half the poses touch a speck
    half = 0.2
    u = np.linspace(-half, half, 81)  # 5 mm sampling
    gu, gv = np.meshgrid(u, u)
    for _ in range(300):
        x, y = rng.uniform(0.5, 2.5, 2)
        th = rng.uniform(-math.pi, math.pi)
        px = x + gu * math.cos(th) - gv * math.sin(th)
        py = y + gu * math.sin(th) + gv * math.cos(th)
        ix, iy = np.floor(px / RES).astype(int), np.floor(py / RES).astype(int)
        sampled_hit = bool(occ[iy, ix].any())
        if sampled_hit:
            assert footprint_collides(occ, RES, 0.0, 0.0, x, y, th, half)
        elif footprint_collides(occ, RES, 0.0, 0.0, x, y, th, half - 0.001):
            # Possible only if a cell corner pokes less than one sampling step into the square.
            inner = np.linspace(-half + 0.001, half - 0.001, 401)
            gi, gj = np.meshgrid(inner, inner)
            qx = x + gi * math.cos(th) - gj * math.sin(th)
            qy = y + gi * math.sin(th) + gj * math.cos(th)
            assert occ[np.floor(qy / RES).astype(int), np.floor(qx / RES).astype(int)].any()
