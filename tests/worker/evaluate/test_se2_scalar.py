"""The scalar angle folds: bit for bit the formulas each call site had, from Python and numba."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from worker.evaluate.se2 import wrap_angle
from worker.evaluate.se2_scalar import wrap, wrap_fold


def _angles() -> np.ndarray:
    rng = np.random.default_rng(16)
    edges = [0.0, -0.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 2 * math.pi]
    edges += [math.nextafter(-math.pi, -10.0), math.nextafter(math.pi, 10.0), 1e9, -1e9]
    return np.concatenate([rng.uniform(-50, 50, 2000), rng.uniform(-4, 4, 2000), edges])


def _old_fold(a: float) -> float:
    # the copy worker/sim/odometry.py and worker/explore/dwa.py each had (pure Python)
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@njit(cache=False)
def _in_a_kernel(a: np.ndarray) -> np.ndarray:
    out = np.empty((a.shape[0], 2))
    for i in range(a.shape[0]):
        out[i, 0] = wrap(a[i])
        out[i, 1] = wrap_fold(a[i])
    return out


def test_wrap_equals_the_vectorised_wrap_bit_for_bit():
    a = _angles()
    vec = wrap_angle(a)
    from_python = np.array([wrap(float(x)) for x in a])
    assert from_python.tobytes() == vec.tobytes()
    assert _in_a_kernel(a)[:, 0].tobytes() == vec.tobytes()
    assert ((from_python >= -math.pi) & (from_python < math.pi)).all()


def test_wrap_fold_equals_the_old_python_fold_bit_for_bit():
    a = _angles()
    old = np.array([_old_fold(float(x)) for x in a])
    assert np.array([wrap_fold(float(x)) for x in a]).tobytes() == old.tobytes()
    assert _in_a_kernel(a)[:, 1].tobytes() == old.tobytes()


@pytest.mark.parametrize(("a", "expected"), [(3 * math.pi / 2, -math.pi / 2), (-math.pi, -math.pi)])
def test_hand_cases(a, expected):
    assert wrap(a) == pytest.approx(expected, abs=1e-15)
    assert wrap_fold(a) == pytest.approx(expected, abs=1e-15)


def test_the_two_folds_differ_only_by_rounding_inside():
    # why both exist: the plain fold moves some angles already in [-pi, pi) by an ulp, and
    # the simulator's and the navigation's runs were made with it
    a = np.random.default_rng(3).uniform(-3, 3, 5000)
    fold = np.array([wrap_fold(float(x)) for x in a])
    assert (np.array([wrap(float(x)) for x in a]) == a).all()
    assert np.abs(fold - a).max() < 1e-15 and (fold != a).any()
