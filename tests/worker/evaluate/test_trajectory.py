"""Trajectory validation, duplicate timestamps, and lookup by time."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from worker.errors import InputError
from worker.evaluate.se2 import interpolate
from worker.evaluate.trajectory import Trajectory


def straight(n=11, dt=0.1, v=1.0):
    t = np.arange(n) * dt
    return Trajectory(t, np.column_stack([v * t, np.zeros(n), np.zeros(n)]))


def test_rejects_mismatched_lengths():
    with pytest.raises(InputError, match=r"shape \(3, 3\)"):
        Trajectory(np.arange(3.0), np.zeros((2, 3)))


def test_rejects_non_finite():
    p = np.zeros((3, 3))
    p[1, 0] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        Trajectory(np.arange(3.0), p)


def test_rejects_unsorted_or_repeated_times():
    with pytest.raises(InputError, match="strictly increasing: sample 2"):
        Trajectory(np.array([0.0, 0.1, 0.1]), np.zeros((3, 3)))


def test_angles_are_wrapped_and_arrays_frozen():
    tr = Trajectory(np.array([0.0]), np.array([[0.0, 0.0, 3 * math.pi / 2]]))
    assert tr.poses[0, 2] == pytest.approx(-math.pi / 2)
    with pytest.raises(ValueError):
        tr.poses[0, 0] = 1.0


def test_from_samples_collapses_the_thesis_doubled_lines_and_keeps_the_last():
    # the listener writes each pose twice; a re-published stamp keeps its later estimate
    t = [4215.9, 4215.9, 4216.0, 4216.0, 4216.1, 4216.1]
    p = np.array([[1, 0, 0], [1, 0, 0], [2, 0, 0], [2.5, 0, 0], [3, 0, 0], [3, 0, 0]], dtype=float)
    tr = Trajectory.from_samples(t, p)
    np.testing.assert_array_equal(tr.t, [4215.9, 4216.0, 4216.1])
    np.testing.assert_array_equal(tr.poses[:, 0], [1.0, 2.5, 3.0])


def test_from_samples_sorts_stably():
    tr = Trajectory.from_samples([0.2, 0.0, 0.1], np.array([[2, 0, 0], [0, 0, 0], [1, 0, 0.0]]))
    np.testing.assert_array_equal(tr.poses[:, 0], [0.0, 1.0, 2.0])


def test_poses_at_exact_interpolated_and_out_of_range():
    tr = straight()  # x = t on [0, 1]
    q = np.array([0.3, 0.3 + 4e-6, 0.35, -0.01, 1.0, 1.05])
    p, ok = tr.poses_at(q)
    np.testing.assert_array_equal(ok, [True, True, True, False, True, False])
    np.testing.assert_allclose(p[:3, 0], [0.3, 0.3, 0.35], atol=1e-12)
    # within the 1e-5 s tolerance a sample is taken as is, not interpolated
    assert p[1, 0] == tr.poses[3, 0]


def test_poses_at_refuses_neighbours_beyond_max_gap():
    t = np.array([0.0, 0.1, 0.5, 0.6])
    tr = Trajectory(t, np.column_stack([t, t, np.zeros(4)]))
    p, ok = tr.poses_at([0.05, 0.3, 0.55], max_gap=0.1)
    np.testing.assert_array_equal(ok, [True, False, True])
    _, ok_wide = tr.poses_at([0.3], max_gap=0.25)
    assert ok_wide.all()


def test_poses_at_interpolates_on_se2_like_se2_interpolate(rng):
    n = 200
    t = np.cumsum(rng.uniform(0.05, 0.1, n))  # uneven sampling exercises the search
    poses = np.column_stack(
        [rng.normal(0, 5, n), rng.normal(0, 5, n), rng.uniform(-math.pi, math.pi, n)]
    )
    tr = Trajectory(t, poses)
    q = rng.uniform(t[0], t[-1], 500)
    p, ok = tr.poses_at(q, max_gap=0.2)
    assert ok.all()
    i = np.searchsorted(t, q, side="right") - 1
    i = np.minimum(i, n - 2)
    alpha = (q - t[i]) / (t[i + 1] - t[i])
    expect = interpolate(poses[i], poses[i + 1], alpha)
    np.testing.assert_allclose(p[:, :2], expect[:, :2], atol=1e-9)
    np.testing.assert_allclose(np.cos(p[:, 2] - expect[:, 2]), 1.0, atol=1e-12)


def test_poses_at_on_empty_and_single_sample():
    empty = Trajectory(np.zeros(0), np.zeros((0, 3)))
    _, ok = empty.poses_at([0.0])
    assert not ok.any()
    one = Trajectory(np.array([2.0]), np.array([[1.0, 2.0, 0.5]]))
    p, ok = one.poses_at([2.0, 2.05])
    np.testing.assert_array_equal(ok, [True, False])
    np.testing.assert_array_equal(p[0], [1.0, 2.0, 0.5])


@given(
    st.lists(st.floats(0.001, 5.0), min_size=2, max_size=60),
    st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=30),
)
def test_lookup_finds_the_bracketing_samples_on_any_spacing(steps, fractions):
    # uneven spacing defeats the even-sampling guess; the gallop must still bracket q
    t = np.cumsum(steps)
    tr = Trajectory(t, np.column_stack([t, 2 * t, np.zeros_like(t)]))
    span = t[-1] - t[0]
    q = t[0] + (np.asarray(fractions) * 0.6 + 0.5) * span  # some before, some after
    p, ok = tr.poses_at(q, max_gap=10.0)
    inside = (q >= t[0] - 1e-5) & (q <= t[-1] + 1e-5)
    np.testing.assert_array_equal(ok, inside)
    # x = t along the path, so a correct bracket + linear interpolation returns q itself
    np.testing.assert_allclose(p[ok, 0], np.clip(q[ok], t[0], t[-1]), atol=2e-5)
    np.testing.assert_allclose(p[ok, 1], 2 * p[ok, 0], atol=1e-9)
    exact, ok_exact = tr.poses_at(t, max_gap=0.0)
    assert ok_exact.all() and (exact[:, 0] == t).all()
