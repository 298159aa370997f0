"""SE(2) algebra on poses `[x, y, theta]`, vectorised over `(N, 3)` arrays with broadcasting."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

TWO_PI = 2.0 * np.pi


def wrap_angle(a: ArrayLike) -> NDArray[np.float64] | np.float64:
    """Wrap angles [rad] to [-pi, pi); angles already inside are returned bit for bit.

    `np.mod` can round an angle just below -pi up to exactly 2*pi, which would map to +pi;
    the `where` folds that case back to -pi so the interval stays half-open.
    """
    a = np.asarray(a, dtype=np.float64)
    w = np.mod(a + np.pi, TWO_PI) - np.pi
    w = np.where(w >= np.pi, w - TWO_PI, w)
    return np.where((a >= -np.pi) & (a < np.pi), a, w)


def _as_poses(p: ArrayLike) -> NDArray[np.float64]:
    arr = np.asarray(p, dtype=np.float64)
    if arr.shape[-1:] != (3,):
        raise ValueError(f"poses must have shape (..., 3) [x, y, theta], got {arr.shape}")
    return arr


def _stack(x: NDArray, y: NDArray, theta: NDArray) -> NDArray[np.float64]:
    return np.stack(np.broadcast_arrays(x, y, theta), axis=-1)


def compose(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """a (+) b: the pose b, given in the frame of a, expressed in a's parent frame.

    Shapes `(3,)` or `(N, 3)` broadcast against each other; returns `(..., 3)`.
    """
    a, b = _as_poses(a), _as_poses(b)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = a[..., 0] + c * b[..., 0] - s * b[..., 1]
    y = a[..., 1] + s * b[..., 0] + c * b[..., 1]
    return _stack(x, y, wrap_angle(a[..., 2] + b[..., 2]))


def inverse(a: ArrayLike) -> NDArray[np.float64]:
    """inv(a): the parent frame's origin seen from a, so that compose(a, inverse(a)) = 0."""
    a = _as_poses(a)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    x = -c * a[..., 0] - s * a[..., 1]
    y = s * a[..., 0] - c * a[..., 1]
    return _stack(x, y, wrap_angle(-a[..., 2]))


def relative(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """inv(a) (+) b: the motion from a to b in a's frame (Kuemmerle's d_ij = inv(X_i) X_j).

    Computed directly as R(a.theta)^T (b.xy - a.xy) rather than through `inverse`, which saves
    a rotation and the rounding that comes with it.
    """
    a, b = _as_poses(a), _as_poses(b)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx = b[..., 0] - a[..., 0]
    dy = b[..., 1] - a[..., 1]
    return _stack(c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2]))


def interpolate(p0: ArrayLike, p1: ArrayLike, alpha: ArrayLike) -> NDArray[np.float64]:
    """Pose a fraction `alpha` (0 at p0, 1 at p1) of the way from p0 to p1.

    Translation is linear and the angle moves along the shorter arc, the usual way to
    resample a 2D trajectory between two neighbouring samples (not the SE(2) geodesic,
    which bends the path; for 0.1 s apart samples the two differ by far less than a mm).
    `alpha` is a scalar or `(N,)`.
    """
    p0, p1 = _as_poses(p0), _as_poses(p1)
    alpha = np.asarray(alpha, dtype=np.float64)
    xy = p0[..., :2] + alpha[..., None] * (p1[..., :2] - p0[..., :2])
    theta = wrap_angle(p0[..., 2] + alpha * wrap_angle(p1[..., 2] - p0[..., 2]))
    return _stack(xy[..., 0], xy[..., 1], theta)


def to_matrix(p: ArrayLike) -> NDArray[np.float64]:
    """Homogeneous 3x3 matrices `(..., 3, 3)` of poses `(..., 3)`."""
    p = _as_poses(p)
    c, s = np.cos(p[..., 2]), np.sin(p[..., 2])
    m = np.zeros(p.shape[:-1] + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = c, -s, p[..., 0]
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = s, c, p[..., 1]
    m[..., 2, 2] = 1.0
    return m


def from_matrix(m: ArrayLike) -> NDArray[np.float64]:
    """Poses `(..., 3)` of homogeneous 3x3 matrices `(..., 3, 3)`."""
    m = np.asarray(m, dtype=np.float64)
    theta = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    return _stack(m[..., 0, 2], m[..., 1, 2], wrap_angle(theta))
