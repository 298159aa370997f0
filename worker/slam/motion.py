"""GMapping's odometry motion model (MotionModel::drawFromMotion), vectorised over particles."""

from __future__ import annotations

import numpy as np

from worker.evaluate.se2 import compose, relative


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
