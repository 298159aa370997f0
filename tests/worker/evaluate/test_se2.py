"""SE(2) algebra: hand-derived cases, matrix cross-check, and hypothesis properties."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from worker.evaluate.se2 import (
    compose,
    from_matrix,
    interpolate,
    inverse,
    relative,
    to_matrix,
    wrap_angle,
)

coord = st.floats(-1e3, 1e3, allow_nan=False)
angle = st.floats(-20.0, 20.0, allow_nan=False)
pose = st.tuples(coord, coord, angle).map(np.array)
poses = st.integers(1, 8).flatmap(
    lambda n: st.tuples(
        arrays(np.float64, (n, 2), elements=coord), arrays(np.float64, (n,), elements=angle)
    ).map(lambda a: np.column_stack([a[0], a[1]]))
)


def assert_pose_close(a, b, atol=1e-7):
    a, b = np.asarray(a), np.asarray(b)
    np.testing.assert_allclose(a[..., :2], b[..., :2], atol=atol, rtol=0)
    # angles compare on the circle
    np.testing.assert_allclose(wrap_angle(a[..., 2] - b[..., 2]), 0.0, atol=atol)


def test_wrap_angle_hand_values():
    np.testing.assert_allclose(
        wrap_angle([0.0, math.pi, -math.pi, 3 * math.pi / 2, -3 * math.pi / 2, 7.0]),
        [0.0, -math.pi, -math.pi, -math.pi / 2, math.pi / 2, 7.0 - 2 * math.pi],
    )


@given(st.floats(-1e6, 1e6, allow_nan=False))
def test_wrap_angle_is_half_open_and_preserves_the_angle(a):
    w = float(wrap_angle(a))
    assert -math.pi <= w < math.pi
    assert math.isclose(math.cos(w), math.cos(a), abs_tol=1e-6)
    assert math.isclose(math.sin(w), math.sin(a), abs_tol=1e-6)


def test_wrap_angle_fold_at_minus_pi():
    # just below -pi, (a + pi) mod 2pi rounds up to exactly 2pi: the naive fold gives +pi
    a = np.nextafter(-np.pi, -np.inf)
    assert np.mod(a + np.pi, 2 * np.pi) - np.pi == np.pi  # the trap exists
    assert float(wrap_angle(a)) == -np.pi


def test_compose_hand_derived():
    # a at (1, 2) facing +y; b is 1 m ahead and 0 m left in a's frame -> (1, 3), facing -x
    a = np.array([1.0, 2.0, math.pi / 2])
    b = np.array([1.0, 0.0, math.pi / 2])
    assert_pose_close(compose(a, b), [1.0, 3.0, math.pi])


def test_relative_hand_derived_kummerle_example():
    # the thesis's relation: from t1 rotate by yaw then translate (x, y) in the first frame
    x1 = np.array([10.0, -3.0, 0.3])
    d = np.array([0.422330, -0.000750, 0.017260])
    x2 = compose(x1, d)
    assert_pose_close(relative(x1, x2), d)


@given(pose, pose)
def test_compose_matches_homogeneous_matrices(a, b):
    assert_pose_close(compose(a, b), from_matrix(to_matrix(a) @ to_matrix(b)), atol=1e-6)


@given(pose)
def test_inverse_gives_identity(a):
    assert_pose_close(compose(a, inverse(a)), [0.0, 0.0, 0.0], atol=1e-6)
    assert_pose_close(compose(inverse(a), a), [0.0, 0.0, 0.0], atol=1e-6)


@given(pose, pose, pose)
def test_compose_is_associative(a, b, c):
    assert_pose_close(compose(compose(a, b), c), compose(a, compose(b, c)), atol=1e-5)


@given(pose, pose)
def test_relative_is_inverse_then_compose(a, b):
    assert_pose_close(relative(a, b), compose(inverse(a), b), atol=1e-6)
    assert_pose_close(compose(a, relative(a, b)), b, atol=1e-6)


@given(poses)
def test_vectorised_equals_row_by_row(p):
    q = p[::-1].copy()
    out = compose(p, q)
    assert out.shape == p.shape
    for k in range(p.shape[0]):
        assert_pose_close(out[k], compose(p[k], q[k]))
    assert (wrap_angle(out[:, 2]) == out[:, 2]).all()


def test_broadcasting_single_pose_against_many():
    many = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 1.0], [2.0, 2.0, -2.0]])
    a = np.array([5.0, -1.0, 0.5])
    out = compose(a, many)
    assert out.shape == (3, 3)
    for k in range(3):
        assert_pose_close(out[k], compose(a, many[k]))


@given(pose, pose)
def test_interpolate_end_points(a, b):
    assert_pose_close(interpolate(a, b, 0.0), a)
    assert_pose_close(interpolate(a, b, 1.0), b, atol=1e-6)


def test_interpolate_takes_the_shorter_arc():
    a = np.array([0.0, 0.0, math.pi - 0.1])
    b = np.array([2.0, 4.0, -math.pi + 0.1])
    mid = interpolate(a, b, 0.5)
    assert_pose_close(mid, [1.0, 2.0, -math.pi])  # through pi, not through 0
    quarter = interpolate(a, b, 0.25)
    assert_pose_close(quarter, [0.5, 1.0, math.pi - 0.05])


def test_interpolate_vector_alpha():
    a = np.zeros((3, 3))
    b = np.array([[1.0, 0.0, 1.0]] * 3)
    out = interpolate(a, b, np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(out, [[0, 0, 0], [0.5, 0, 0.5], [1, 0, 1]])


def test_bad_shape_is_rejected():
    with pytest.raises(ValueError, match=r"\(\.\.\., 3\)"):
        compose(np.zeros(2), np.zeros(3))
