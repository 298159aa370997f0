"""SE(2) helpers and GMapping's odometry motion model (MotionModel::drawFromMotion)."""

from __future__ import annotations

import numpy as np


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Angles wrapped to [-pi, pi)."""
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2 * np.pi) - np.pi


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a (+) b: pose b, expressed in frame a, in a's parent frame. (..., 3) broadcasting."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return np.stack([x, y, wrap_angle(a[..., 2] + b[..., 2])], axis=-1)


def inverse(a: np.ndarray) -> np.ndarray:
    """The inverse transform of a: compose(a, inverse(a)) = 0. (..., 3)."""
    a = np.asarray(a, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return np.stack([x, y, wrap_angle(-a[..., 2])], axis=-1)


def relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """inv(a) (+) b: pose b in frame a (GMapping's absoluteDifference(b, a))."""
    return compose(inverse(a), b)


def draw_from_motion(
    poses: np.ndarray,
    odom_new: np.ndarray,
    odom_old: np.ndarray,
    srr: float,
    srt: float,
    str_: float,
    stt: float,
    rng: np.random.Generator,
) -> np.ndarray:
    """Sample new particle poses from the odometry step odom_old -> odom_new.

    poses: (N, 3) [x, y, theta]; returns (N, 3). As GMapping's drawFromMotion: the step
    delta in the old odometry frame gets Gaussian noise with standard deviations
      x:     srr |dx| + str |dtheta| + 0.3 srr |dy|
      y:     srr |dy| + str |dtheta| + 0.3 srr |dx|
      theta: stt |dtheta| + srt sqrt(dx^2 + dy^2)
    and is composed onto each particle. One (N, 3) standard normal draw per call.
    """
    delta = relative(odom_old, odom_new)
    dx, dy, dth = abs(delta[0]), abs(delta[1]), abs(delta[2])
    sxy = 0.3 * srr
    std = np.array(
        [
            srr * dx + str_ * dth + sxy * dy,
            srr * dy + str_ * dth + sxy * dx,
            stt * dth + srt * np.hypot(dx, dy),
        ]
    )
    noisy = delta + rng.standard_normal((poses.shape[0], 3)) * std
    return compose(poses, noisy)
