"""Scalar SE(2) angle helpers as numba functions, callable from kernels and from Python alike.

The vectorised algebra over `(N, 3)` arrays is `worker.evaluate.se2`; these are the one-float
versions the per-step code paths need (numpy's call overhead dominates on a single number).

Two folds exist, and each call site keeps the one it always had, so runs stay bit for bit:
`wrap` returns angles already in [-pi, pi) unchanged (as `se2.wrap_angle`), for the SLAM and
the metric; `wrap_fold` always computes `(a + pi) mod 2 pi - pi`, which may move an angle
already inside by an ulp, as the simulator's odometry and the navigation stack have done since
their first version.
"""

from __future__ import annotations

import math

from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always")
def wrap(a: float) -> float:
    """Angle [rad] wrapped to [-pi, pi); angles already inside are returned bit for bit.

    The modulo can round an angle just below -pi up to exactly 2 pi, which would give +pi;
    that case is folded back to -pi so the interval stays half-open (as `se2.wrap_angle`).
    """
    if -math.pi <= a < math.pi:
        return a
    w = (a + math.pi) % TWO_PI - math.pi
    if w >= math.pi:
        w -= TWO_PI
    return w


@njit(cache=True, inline="always")
def wrap_fold(a: float) -> float:
    """Angle [rad] folded to [-pi, pi) by `(a + pi) mod 2 pi - pi`, for every input.

    Unlike `wrap`, an angle already inside may come back one ulp off; kept for the simulator
    and the navigation stack, whose runs depend on it.
    """
    return (a + math.pi) % TWO_PI - math.pi
