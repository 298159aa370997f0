"""A SLAM problem from a corrected log: its real scans, odometry made to drift, its poses as truth.

A corrected CARMEN log (the Radish logs in `../shared/data/carmen/`) carries real scans and,
as their poses, the trajectory after offline correction: the reference Kuemmerle et al. (2009)
use for these buildings. Its own odometry does not match the scans' clock and frame in every
log, so the problem's odometry is made here, under control and seeded:

  delta_k = inv(g_k) (+) g_(k+1)                      the corrected step, in the robot frame
  s       = 1 + scale_std * N(0, I_3)                 one scale error per axis (x, y, theta) a run
  e_k     = step_noise * |delta_k| * N(0, I_3)        noise on each step, per component
  o_0 = g_0,   o_(k+1) = o_k (+) (s * delta_k + e_k)  the drifting odometry

so the odometry starts at the true pose and drifts away from it: a scale error per axis (a
wheel radius, a wheel base off by a few percent) and per-step noise (slip). Ground truth is the
corrected poses at the scans' times (the clock rule of `worker.evaluate.clock` already applied).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory
from worker.sim.carmen import CarmenWriter, LaserLog


@dataclass(frozen=True)
class DriftParams:
    """How the problem's odometry drifts (defaults: issue 17's 3 % scale, 5 % per-step noise)."""

    scale_std: float = 0.03  # [1] std of the per-run scale error of each axis (x, y, theta)
    step_noise: float = 0.05  # [1] per-step noise std, relative to each step component

    def __post_init__(self) -> None:
        for name in ("scale_std", "step_noise"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value < 1.0):
                raise InputError(f"drift parameter {name} must be in [0, 1), got {value}")


def _relative(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 3) inv(a_k) (+) b_k for (N, 3) poses."""
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    dth = (b[:, 2] - a[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, dth])


def drift_odometry(
    pose_gt: np.ndarray, rng: np.random.Generator, params: DriftParams
) -> tuple[np.ndarray, np.ndarray]:
    """(odometry (N, 3), scale (3,)) drifting from the true poses `pose_gt (N, 3)` as the
    module docstring says; one scale draw, then one (N - 1, 3) noise draw."""
    pose_gt = np.asarray(pose_gt, dtype=np.float64).reshape(-1, 3)
    scale = 1.0 + params.scale_std * rng.standard_normal(3)
    steps = _relative(pose_gt[:-1], pose_gt[1:])
    noisy = scale * steps + params.step_noise * np.abs(steps) * rng.standard_normal(steps.shape)
    odom = np.empty_like(pose_gt)
    if pose_gt.shape[0] == 0:
        return odom, scale
    odom[0] = pose_gt[0]
    x, y, th = pose_gt[0]
    for k, (dx, dy, dth) in enumerate(noisy.tolist(), start=1):
        c, s = math.cos(th), math.sin(th)
        x, y = x + c * dx - s * dy, y + s * dx + c * dy
        th = (th + dth + math.pi) % (2.0 * math.pi) - math.pi
        odom[k] = (x, y, th)
    return odom, scale


def drifting_problem(
    log: LaserLog, seed: int, params: DriftParams | None = None
) -> tuple[LaserLog, Trajectory]:
    """(the log with drifting odometry and its corrected poses as TRUEPOS, ground truth).

    log: a corrected log as `read_laser_log` gives it (its scan poses are the reference).
    The same log, seed and params give the same problem, bit for bit.
    """
    params = DriftParams() if params is None else params
    if log.t.shape[0] < 2:
        raise InputError("a SLAM problem needs at least 2 scans", path=log.source)
    rng = np.random.default_rng(seed)
    odom, _ = drift_odometry(log.pose_odom, rng, params)
    gt = Trajectory.from_samples(log.t, log.pose_odom)
    drifted = dataclasses.replace(
        log,
        pose_odom=odom,
        t_gt=log.t.copy(),
        pose_gt=log.pose_odom.copy(),
        t_odom=log.t.copy(),
        odom=odom,
    )
    return drifted, gt


def log_slice(log: LaserLog, start: int, stop: int) -> LaserLog:
    """Scans start..stop-1 of a log (and its TRUEPOS / ODOM samples within their times)."""
    if not 0 <= start < stop:
        raise InputError(f"a slice needs 0 <= start < stop, got {start}..{stop}")
    t = log.t[start:stop]

    def within(tt: np.ndarray | None) -> np.ndarray:
        return np.zeros(0, dtype=bool) if tt is None else (tt >= t[0]) & (tt <= t[-1])

    gt_in, odom_in = within(log.t_gt), within(log.t_odom)
    return dataclasses.replace(
        log,
        t=t,
        ranges=log.ranges[start:stop],
        pose_odom=log.pose_odom[start:stop],
        t_gt=None if log.t_gt is None else log.t_gt[gt_in],
        pose_gt=None if log.pose_gt is None else log.pose_gt[gt_in],
        t_odom=log.t_odom[odom_in],
        odom=log.odom[odom_in],
    )


def write_problem_log(path: str | Path, log: LaserLog, comment: str | None = None) -> None:
    """The log as CARMEN ODOM, ROBOTLASER1 and TRUEPOS lines, one of each per scan (needs
    the TRUEPOS poses at the scans' times, as `drifting_problem` gives them)."""
    if log.pose_gt is None or log.t_gt is None or log.t_gt.shape != log.t.shape:
        raise InputError("the log needs one ground-truth pose per scan", path=log.source)
    try:
        with open(path, "w", encoding="utf-8") as fh:
            writer = CarmenWriter(fh, log.laser, comment)
            for k in range(log.t.shape[0]):
                writer.write_tick(
                    float(log.t[k]), log.pose_gt[k], log.pose_odom[k], 0.0, 0.0, log.ranges[k]
                )
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror}", path=path) from None
