"""GMapping's motion model sampling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.slam.motion import draw_from_motion


def test_noise_free_motion_is_exact(rng):
    poses = np.array([[0.0, 0.0, 0.0], [5.0, -1.0, math.pi / 2]])
    old = np.array([1.0, 1.0, 0.0])
    new = np.array([2.0, 1.0, 0.3])  # 1 m forward then turn 0.3 rad
    out = draw_from_motion(poses, new, old, 0, 0, 0, 0, rng)
    assert np.allclose(out[0], [1.0, 0.0, 0.3])
    assert np.allclose(out[1], [5.0, 0.0, math.pi / 2 + 0.3])


def test_motion_noise_follows_gmapping_formula(rng):
    # a pure 1 m forward step: std x = srr * 1, y = 0.3 srr * 1, theta = srt * 1
    poses = np.zeros((20000, 3))
    out = draw_from_motion(poses, np.array([1.0, 0, 0]), np.zeros(3), 0.1, 0.2, 0.1, 0.2, rng)
    assert abs(out[:, 0].mean() - 1.0) < 0.01
    # y and theta noise compose: small angles, so y ~ noise_y (+ 1 m * sin(noise_theta) / 1)
    assert abs(out[:, 2].std() - 0.2) < 0.01
    assert abs(out[:, 0].std() - 0.1) < 0.01
    # a pure rotation of 0.5 rad: theta std = stt * 0.5, x and y std = str * 0.5
    out = draw_from_motion(poses, np.array([0, 0, 0.5]), np.zeros(3), 0.1, 0.2, 0.1, 0.2, rng)
    assert abs(out[:, 2].std() - 0.1) < 0.005
    assert abs(out[:, 0].std() - 0.05) < 0.003 and abs(out[:, 1].std() - 0.05) < 0.003


def test_scalar_helpers_equal_the_vectorised_se2(rng):
    from worker.evaluate.se2 import compose, relative, wrap_angle
    from worker.evaluate.se2_scalar import wrap
    from worker.slam.motion import compose3, relative3

    angles = np.concatenate([rng.uniform(-20, 20, 200), [-math.pi, math.pi, 3 * math.pi, 0.0]])
    for a in angles:
        assert wrap(a) == float(wrap_angle(a))
    for _ in range(50):
        a, b = rng.uniform(-5, 5, 3), rng.uniform(-5, 5, 3)
        assert np.allclose(compose3(a, b), compose(a, b), rtol=0, atol=1e-12)
        assert np.allclose(relative3(a, b), relative(a, b), rtol=0, atol=1e-12)


def test_a_long_step_is_drawn_as_the_robot_sized_steps_it_stands_for():
    # 1 m straight with substeps of 0.1 m: k = 10 steps, std srr * 1 m / sqrt(10) in x and
    # srt * 1 m / sqrt(10) in theta (by hand from the docstring's formula)
    rng = np.random.default_rng(3)
    poses = np.zeros((20000, 3))
    out = draw_from_motion(
        poses, np.array([1.0, 0, 0]), np.zeros(3), 0.1, 0.2, 0.1, 0.2, rng, (0.1, 0.1)
    )
    assert out[:, 0].std() == pytest.approx(0.1 / np.sqrt(10), rel=0.03)
    assert out[:, 2].std() == pytest.approx(0.2 / np.sqrt(10), rel=0.03)
    # a turn of 0.5 rad with 0.1 rad substeps: k = 5
    out = draw_from_motion(
        poses, np.array([0, 0, 0.5]), np.zeros(3), 0.1, 0.2, 0.1, 0.2, rng, (0.1, 0.1)
    )
    assert out[:, 2].std() == pytest.approx(0.2 * 0.5 / np.sqrt(5), rel=0.03)


def test_a_step_within_the_substep_is_drawn_as_gmapping_draws_it():
    poses = np.zeros((50, 3))
    step = np.array([0.08, 0.01, 0.06])  # a 10 Hz step under 0.85 m/s and 0.7 rad/s
    a = draw_from_motion(poses, step, np.zeros(3), 0.1, 0.2, 0.1, 0.2, np.random.default_rng(1))
    b = draw_from_motion(
        poses, step, np.zeros(3), 0.1, 0.2, 0.1, 0.2, np.random.default_rng(1), (0.1, 0.1)
    )
    np.testing.assert_array_equal(a, b)
