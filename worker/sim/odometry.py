"""Odometry error models: Stage's per-run scale factors, or per-step Gaussian noise."""

from __future__ import annotations

import math

from worker.evaluate.se2_scalar import wrap_fold


def relative_motion(x0, y0, t0, x1, y1, t1) -> tuple[float, float, float]:
    """Motion from pose 0 to pose 1 in pose 0's frame: (dx, dy, dtheta), i.e. inv(X0) X1."""
    c, s = math.cos(t0), math.sin(t0)
    ex, ey = x1 - x0, y1 - y0
    return c * ex + s * ey, -s * ex + c * ey, wrap_fold(t1 - t0)


def compose(x, y, t, dx, dy, dt) -> tuple[float, float, float]:
    """Apply a motion (dx, dy, dtheta) given in the frame of pose (x, y, t): X (+) d."""
    c, s = math.cos(t), math.sin(t)
    return x + c * dx - s * dy, y + s * dx + c * dy, wrap_fold(t + dt)


def stage_increment(d: tuple[float, float, float], factors) -> tuple[float, float, float]:
    """Stage: each component of the true increment scaled by (1 + its per-run error factor)."""
    return d[0] * (1.0 + factors[0]), d[1] * (1.0 + factors[1]), d[2] * (1.0 + factors[2])


def gaussian_increment(
    d: tuple[float, float, float], sigmas: tuple[float, float, float], rng
) -> tuple[float, float, float]:
    """Per-step Gaussian: std of x/y error = sigma_trans * distance, of theta error =
    sigma_rot * |dtheta| + sigma_rot_per_m * distance (the usual odometry motion model)."""
    trans = math.hypot(d[0], d[1])
    rot = abs(d[2])
    if trans == 0.0 and rot == 0.0:
        return d
    s_xy = sigmas[0] * trans
    s_th = sigmas[1] * rot + sigmas[2] * trans
    e = rng.standard_normal(3)
    return d[0] + s_xy * e[0], d[1] + s_xy * e[1], d[2] + s_th * e[2]
