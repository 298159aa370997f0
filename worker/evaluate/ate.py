"""Absolute trajectory error after a least-squares SE(2) alignment (no scale), secondary figure."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from worker.errors import InputError
from worker.evaluate.metric import error_stats
from worker.evaluate.se2 import compose, wrap_angle
from worker.evaluate.trajectory import DEFAULT_MAX_GAP_S, Trajectory


def align_se2(src_xy: NDArray[np.float64], dst_xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """The pose T `[x, y, theta]` minimising sum |R(theta) src_i + t - dst_i|^2, both `(K, 2)`.

    Umeyama/Horn without scale, in closed form for 2D: with centred points p, q the optimal
    angle is atan2(sum p x q, sum p . q), and t = mean(dst) - R mean(src).
    """
    ps = src_xy.mean(axis=0)
    qs = dst_xy.mean(axis=0)
    p = src_xy - ps
    q = dst_xy - qs
    cross = float(np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0]))
    dot = float(np.sum(p[:, 0] * q[:, 0] + p[:, 1] * q[:, 1]))
    theta = math.atan2(cross, dot)
    c, s = math.cos(theta), math.sin(theta)
    tx = qs[0] - (c * ps[0] - s * ps[1])
    ty = qs[1] - (s * ps[0] + c * ps[1])
    return np.array([tx, ty, float(wrap_angle(theta))])


@dataclass(frozen=True)
class AteResult:
    """ATE of an estimate against ground truth.

    t: (K,) [s] ground-truth times the estimate could provide.
    translation: (K,) [m] |xy_gt - xy_aligned_est|; rotation: (K,) [rad] |wrap(theta diff)|.
    alignment: (3,) [x, y, theta] T_gt_est applied to the estimate.
    skipped: ground-truth samples with no estimate within max_gap.
    """

    t: NDArray[np.float64]
    translation: NDArray[np.float64]
    rotation: NDArray[np.float64]
    alignment: NDArray[np.float64]
    skipped: int

    def summary(self) -> dict[str, Any]:
        """`{"translation": {rmse, mean, std, min, max, n, mean_squared}, "rotation": {...},
        "alignment": {x, y, theta}, "skipped": int}`."""
        out: dict[str, Any] = {}
        for name, err in (("translation", self.translation), ("rotation", self.rotation)):
            stats = error_stats(err)
            ms = stats["mean_squared"]
            out[name] = {"rmse": None if ms is None else math.sqrt(ms), **stats}
        x, y, th = (float(v) for v in self.alignment)
        out["alignment"] = {"x": x, "y": y, "theta": th}
        out["skipped"] = self.skipped
        return out


def absolute_trajectory_error(
    gt: Trajectory, est: Trajectory, max_gap: float = DEFAULT_MAX_GAP_S
) -> AteResult:
    """ATE: the estimate at each ground-truth time (lookup as in the relations metric),
    rigidly aligned to the ground truth in least squares, then the per-pose errors."""
    est_at, ok = est.poses_at(gt.t, max_gap=max_gap)
    if not ok.any():
        raise InputError(
            "no ground-truth time could be matched in the estimate (check timestamps and max_gap)"
        )
    gt_p = gt.poses[ok]
    align = align_se2(est_at[ok, :2], gt_p[:, :2])
    est_aligned = compose(align, est_at[ok])
    trans = np.hypot(est_aligned[:, 0] - gt_p[:, 0], est_aligned[:, 1] - gt_p[:, 1])
    rot = np.abs(wrap_angle(est_aligned[:, 2] - gt_p[:, 2]))
    return AteResult(gt.t[ok], trans, rot, align, int(ok.size - np.count_nonzero(ok)))
