"""Sanity checks of an estimate against the run's ground truth, each a one-line InputError:
timestamps not covering the run (milliseconds or nanoseconds for seconds, a clock offset),
millimetres for metres (path length), a frame offset or rotated from the run's (first pose),
a mirrored frame, degrees for radians (turning).

The relations metric itself is blind to a constant frame offset (d = inv(X1) X2 cancels it),
so an offset frame is refused only because it almost always means the wrong topic or frame;
`CheckParams(frame=False)` scores it all the same.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from worker.errors import InputError
from worker.evaluate.se2 import wrap_angle
from worker.evaluate.trajectory import Trajectory

FAR_S = 1e12  # [s] a max_gap that always interpolates (the checks look at shape, not gaps)
_UNITS = ((1e3, "milliseconds"), (1e6, "microseconds"), (1e9, "nanoseconds"))


@dataclass(frozen=True)
class CheckParams:
    """Tolerances of the checks."""

    cover_tol: float = 0.5  # [s] the estimate may start later / end earlier than the run by this
    cover_share: float = 0.01  # ... plus this share of the run's length (relations left: skipped)
    frame_xy_tol: float = 0.3  # [m] first pose of the estimate vs the ground truth's
    frame_theta_tol: float = 0.1  # [rad] the same for the heading
    degrees_ratio: float = 8.0  # estimate's turning over the ground truth's above this: degrees
    min_turn: float = 0.5  # [rad] the ground truth must turn this much for the two turn checks
    frame: bool = True  # refuse an offset, rotated or mirrored frame
    max_coordinate: float = 1e6  # [m] no building is larger: beyond it, not metres
    units_ratio: float = 50.0  # estimate's path over the ground truth's above this: not metres
    min_path: float = 0.5  # [m] the ground truth must travel this much for that check


def check_estimate(est: Trajectory, gt: Trajectory, p: CheckParams, name: str = "estimate") -> None:
    """Raise InputError (one line, naming `name`) for the first problem found."""
    far = float(np.max(np.abs(est.poses[:, :2]))) if len(est) else 0.0
    if far > p.max_coordinate:
        raise InputError(f"{name}: a pose {far:.6g} m from the origin: not metres, or garbage")
    _check_clock(est, gt, p, name)
    common = gt.t[(gt.t >= est.t[0]) & (gt.t <= est.t[-1])]
    if common.shape[0] < 2:
        raise InputError(f"{name}: fewer than 2 ground-truth times inside the estimate's span")
    g, _ = gt.poses_at(common, FAR_S)
    e, _ = est.poses_at(common, FAR_S)
    path_gt = float(np.sum(np.hypot(*np.diff(g[:, :2], axis=0).T)))
    path_est = float(np.sum(np.hypot(*np.diff(e[:, :2], axis=0).T)))
    if path_gt > p.min_path and path_est > p.units_ratio * path_gt:
        raise InputError(
            f"{name}: it travels {path_est:.6g} where the ground truth travels {path_gt:.3f} m "
            f"({path_est / path_gt:.0f} x): positions in millimetres (or centimetres) for metres?"
        )
    if p.frame:
        _check_first_pose(e[0], g[0], float(common[0]), p, name)
    d_gt, d_est = wrap_angle(np.diff(g[:, 2])), wrap_angle(np.diff(e[:, 2]))
    turn_gt = float(np.sum(np.abs(d_gt)))
    if turn_gt < p.min_turn:
        return
    turn_est = float(np.sum(np.abs(d_est)))
    if turn_est > p.degrees_ratio * turn_gt:
        raise InputError(
            f"{name}: it turns {turn_est:.1f} rad where the ground truth turns {turn_gt:.1f} rad "
            f"({turn_est / turn_gt:.0f} x): headings in degrees instead of radians?"
        )
    if p.frame and float(np.dot(d_gt, d_est)) < -0.5 * turn_gt * turn_gt / max(len(d_gt), 1):
        corr = float(np.dot(d_gt, d_est) / (np.linalg.norm(d_gt) * np.linalg.norm(d_est) + 1e-300))
        if corr < -0.5:
            raise InputError(
                f"{name}: it turns left where the ground truth turns right (correlation "
                f"{corr:.2f}): a mirrored frame (y axis flipped)?"
            )


def _check_clock(est: Trajectory, gt: Trajectory, p: CheckParams, name: str) -> None:
    g0, g1, e0, e1 = float(gt.t[0]), float(gt.t[-1]), float(est.t[0]), float(est.t[-1])
    span = f"its timestamps span {e0:.6g}..{e1:.6g} s, the run's {g0:.6g}..{g1:.6g} s"
    run_len, est_len = g1 - g0, e1 - e0
    if run_len > 0 and est_len > 0:  # first: a run from t = 0 in ms still "covers" the run
        for factor, unit in _UNITS:
            if 0.5 * factor <= est_len / run_len <= 2.0 * factor:
                raise InputError(f"{name}: {span}: timestamps in {unit} instead of seconds?")
    slack = p.cover_tol + p.cover_share * run_len  # a SLAM may publish its first pose late
    if e0 <= g0 + slack and e1 >= g1 - slack:
        return
    if run_len > 0 and est_len > 0 and abs(est_len - run_len) <= slack:
        raise InputError(
            f"{name}: {span}: the same length shifted by {e0 - g0:.6g} s (a clock offset: "
            "stamps from the wall clock instead of the bag's?)"
        )
    raise InputError(f"{name}: {span}: it does not cover the run")


def _check_first_pose(e: np.ndarray, g: np.ndarray, t: float, p: CheckParams, name: str) -> None:
    dxy = float(np.hypot(e[0] - g[0], e[1] - g[1]))
    dth = float(abs(wrap_angle(np.array([e[2] - g[2]]))[0]))
    if dxy > p.frame_xy_tol or dth > p.frame_theta_tol:
        raise InputError(
            f"{name}: at t={t:.6g} s it is at ({e[0]:.3f}, {e[1]:.3f}, {e[2]:.3f}), the ground "
            f"truth at ({g[0]:.3f}, {g[1]:.3f}, {g[2]:.3f}): {dxy:.3f} m, {dth:.3f} rad apart, "
            "a frame offset or rotated from the run's (map) frame"
        )
