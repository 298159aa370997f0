"""A timestamped 2D trajectory and its lookup by time (exact sample or SE(2) interpolation)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from worker.errors import InputError
from worker.evaluate.lookup_kernels import TIME_TOL_S, lookup_poses
from worker.evaluate.se2 import wrap_angle

DEFAULT_MAX_GAP_S = 0.1  # [s] the farthest a neighbour may be from a looked-up time


@dataclass(frozen=True, eq=False)  # arrays: identity equality, hashable
class Trajectory:
    """Poses over time.

    t: (N,) float64 [s], strictly increasing.
    poses: (N, 3) float64 [x, y, theta] (m, m, rad), theta wrapped to [-pi, pi).

    The constructor validates and refuses duplicate timestamps; build from raw samples
    (a log may repeat or reorder lines) with `Trajectory.from_samples`.
    """

    t: NDArray[np.float64]
    poses: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.ascontiguousarray(self.t, dtype=np.float64)
        poses = np.ascontiguousarray(self.poses, dtype=np.float64)
        if t.ndim != 1:
            raise InputError(f"trajectory times must have shape (N,), got {t.shape}")
        if poses.shape != (t.shape[0], 3):
            raise InputError(
                f"trajectory poses must have shape ({t.shape[0]}, 3) to match {t.shape[0]} "
                f"timestamps, got {poses.shape}"
            )
        if not (np.isfinite(t).all() and np.isfinite(poses).all()):
            raise InputError("trajectory contains non-finite values (nan or inf)")
        if t.shape[0] > 1 and not (np.diff(t) > 0).all():
            k = int(np.argmax(np.diff(t) <= 0))
            raise InputError(
                f"trajectory timestamps must be strictly increasing: sample {k + 1} at "
                f"t={t[k + 1]!r} follows t={t[k]!r}"
            )
        poses = poses.copy()
        poses[:, 2] = wrap_angle(poses[:, 2])
        packed = np.column_stack([t, poses]) if t.shape[0] else np.zeros((0, 4))
        for arr in (t, poses, packed):
            arr.setflags(write=False)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "poses", poses)
        object.__setattr__(self, "_packed", packed)

    @property
    def packed(self) -> NDArray[np.float64]:
        """`(N, 4) [t, x, y, theta]`, the row-per-sample layout the lookup kernels use."""
        return self._packed

    @classmethod
    def from_samples(
        cls, t: ArrayLike, poses: ArrayLike, path: str | Path | None = None
    ) -> Trajectory:
        """Trajectory from samples as a log gives them: sorted by time (stable), and of
        several samples with the same timestamp the one written last is kept.

        The thesis's listener writes every pose twice (identical lines); a logger that
        re-publishes a stamp after a correction means its later estimate, hence "last".
        """
        t = np.asarray(t, dtype=np.float64)
        poses = np.asarray(poses, dtype=np.float64)
        if t.ndim != 1 or poses.shape != (t.shape[0], 3):
            raise InputError(
                f"expected t (N,) and poses (N, 3), got {t.shape} and {poses.shape}", path=path
            )
        if not (np.isfinite(t).all() and np.isfinite(poses).all()):
            raise InputError("trajectory contains non-finite values (nan or inf)", path=path)
        order = np.argsort(t, kind="stable")
        t, poses = t[order], poses[order]
        # keep the last of each run of equal timestamps
        keep = np.ones(t.shape[0], dtype=bool)
        keep[:-1] = t[1:] != t[:-1]
        return cls(t[keep], poses[keep])

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from the first to the last sample [s]."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    def poses_at(
        self, times: ArrayLike, max_gap: float = DEFAULT_MAX_GAP_S
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Poses `(M, 3)` at `times (M,)` and `ok (M,)`.

        A time within 1e-5 s of a sample takes that sample; otherwise the pose is
        interpolated (`se2.interpolate`) between the neighbours before and after, only when
        both lie within `max_gap` [s]. Rows that cannot be looked up are 0 with ok False.
        """
        q = np.ascontiguousarray(times, dtype=np.float64).reshape(-1)
        return lookup_poses(self._packed, q, float(max_gap), TIME_TOL_S)
