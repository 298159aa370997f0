"""GMapping's odometry motion model (MotionModel::drawFromMotion) and scalar SE(2) helpers for
the per-scan path (numpy's call overhead dominates on a handful of numbers)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worker.evaluate.se2_scalar import wrap


@njit(cache=True)
def compose3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a (+) b for two (3,) poses [x, y, theta]."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], wrap(a[2] + b[2])])


@njit(cache=True)
def relative3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """inv(a) (+) b for two (3,) poses: the motion from a to b in a's frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, wrap(b[2] - a[2])])


@njit(cache=True)
def _noisy_steps(poses, delta, std, noise):
    """Each pose (N, 3) composed with delta (3,) + noise (N, 3) * std (3,)."""
    out = np.empty_like(poses)
    for p in range(poses.shape[0]):
        bx = delta[0] + noise[p, 0] * std[0]
        by = delta[1] + noise[p, 1] * std[1]
        bt = delta[2] + noise[p, 2] * std[2]
        c, s = math.cos(poses[p, 2]), math.sin(poses[p, 2])
        out[p, 0] = poses[p, 0] + c * bx - s * by
        out[p, 1] = poses[p, 1] + s * bx + c * by
        out[p, 2] = wrap(poses[p, 2] + bt)
    return out


def motion_substeps(dist: float, turn: float, substep: tuple[float, float]) -> int:
    """How many steps of at most substep = (lmax [m], amax [rad]) make up a step (1: one)."""
    lmax, amax = substep
    k = 1.0
    if lmax > 0.0:
        k = max(k, dist / lmax)
    if amax > 0.0:
        k = max(k, turn / amax)
    return math.ceil(k)


def draw_from_motion(
    poses: np.ndarray,
    odom_new: np.ndarray,
    odom_old: np.ndarray,
    srr: float,
    srt: float,
    str_: float,
    stt: float,
    rng: np.random.Generator,
    substep: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """Sample new particle poses from the odometry step odom_old -> odom_new.

    poses: (N, 3) [x, y, theta]; returns (N, 3). As GMapping's drawFromMotion: the step
    delta in the old odometry frame gets Gaussian noise with standard deviations
      x:     srr |dx| + str |dtheta| + 0.3 srr |dy|
      y:     srr |dy| + str |dtheta| + 0.3 srr |dx|
      theta: stt |dtheta| + srt sqrt(dx^2 + dy^2)
    and is composed onto each particle. One (N, 3) standard normal draw per call.

    substep (lmax [m], amax [rad]): a step longer than lmax or turning more than amax (a log
    that kept one scan a metre, as the corrected Radish logs) is drawn as the k equal steps
    of at most that size a robot's odometry would have given, k = ceil(max(|d| / lmax,
    |dtheta| / amax)): the k independent noises of std/k sum to std/sqrt(k). A step within
    both (every step of a 10 Hz log of a robot under lmax / 0.1 s), or (0, 0), is drawn as GMapping
    draws it, bit for bit.
    """
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    delta = relative3(
        np.asarray(odom_old, dtype=np.float64), np.asarray(odom_new, dtype=np.float64)
    )
    std = motion_std(delta, srr, srt, str_, stt, substep)
    noise = rng.standard_normal((poses.shape[0], 3))
    return _noisy_steps(poses, delta, std, noise)


def motion_std(
    delta: np.ndarray,
    srr: float,
    srt: float,
    str_: float,
    stt: float,
    substep: tuple[float, float] = (0.0, 0.0),
) -> np.ndarray:
    """(3,) the standard deviations [m, m, rad] draw_from_motion gives the step delta (3,)
    (robot frame of the pose before it), divided by sqrt(k) for a step of k substeps."""
    dx, dy, dth = abs(delta[0]), abs(delta[1]), abs(delta[2])
    sxy = 0.3 * srr
    std = np.array(
        [
            srr * dx + str_ * dth + sxy * dy,
            srr * dy + str_ * dth + sxy * dx,
            stt * dth + srt * math.hypot(dx, dy),
        ]
    )
    k = motion_substeps(math.hypot(dx, dy), dth, substep)
    if k > 1:
        std = std / math.sqrt(k)
    return std
