"""Relations (Kuemmerle et al. 2009) and their generators A, B, SM, L, M, S from ground truth."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from worker.errors import InputError
from worker.evaluate.lookup_kernels import TIME_TOL_S, relation_errors
from worker.evaluate.params import AParams, BParams, LParams, MParams, SMParams, SParams
from worker.evaluate.relation_kernels import (
    distance_anchors,
    far_pair_counts,
    far_pairs_fill,
    leave_index,
    pair_deltas,
)
from worker.evaluate.trajectory import Trajectory

RelationKind = Literal["A", "B", "SM", "L", "M", "S"]


@dataclass(frozen=True, eq=False)  # arrays: identity equality, hashable
class Relations:
    """Relative motions between ground-truth poses, d*_ij = inv(X*_i) X*_j.

    t1, t2: (M,) float64 [s] the two timestamps.
    delta: (M, 3) float64 [x, y, theta] the motion from the pose at t1 to the pose at t2,
        in the frame of the first (m, m, rad).
    """

    t1: NDArray[np.float64]
    t2: NDArray[np.float64]
    delta: NDArray[np.float64]

    def __post_init__(self) -> None:
        t1 = np.ascontiguousarray(self.t1, dtype=np.float64).reshape(-1)
        t2 = np.ascontiguousarray(self.t2, dtype=np.float64).reshape(-1)
        delta = np.ascontiguousarray(self.delta, dtype=np.float64)
        if t2.shape != t1.shape or delta.shape != (t1.shape[0], 3):
            raise InputError(
                f"relations need t1 (M,), t2 (M,), delta (M, 3), got "
                f"{t1.shape}, {t2.shape}, {delta.shape}"
            )
        if not (np.isfinite(t1).all() and np.isfinite(t2).all() and np.isfinite(delta).all()):
            raise InputError("relations contain non-finite values (nan or inf)")
        for name, arr in (("t1", t1), ("t2", t2), ("delta", delta)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.t1.shape[0])


class RelationsCapWarning(UserWarning):
    """B asked for more relations than the cap allows; the cap was used."""


def _positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive number, got {value!r}")


def _from_indices(gt: Trajectory, i: ArrayLike, j: ArrayLike) -> Relations:
    i = np.ascontiguousarray(i, dtype=np.int64)
    j = np.ascontiguousarray(j, dtype=np.int64)
    return Relations(gt.t[i], gt.t[j], pair_deltas(gt.poses, i, j))


def sample_every(gt: Trajectory, dt: float) -> NDArray[np.int64]:
    """Indices of ground-truth samples every dt [s] from the first: for each grid time the
    first sample at or after it, if within dt/2; no index twice."""
    _positive("dt", dt)
    if len(gt) == 0:
        return np.zeros(0, dtype=np.int64)
    k = int(math.floor(gt.duration / dt + 1e-9))
    grid = gt.t[0] + dt * np.arange(k + 1)
    idx = np.searchsorted(gt.t, grid - TIME_TOL_S, side="left")
    inside = idx < len(gt)
    idx, grid = idx[inside], grid[inside]
    idx = idx[gt.t[idx] - grid <= 0.5 * dt]
    return np.unique(idx)


def _consecutive(gt: Trajectory, idx: NDArray[np.int64]) -> Relations:
    return _from_indices(gt, idx[:-1], idx[1:])


def relations_A(gt: Trajectory, params: AParams = AParams()) -> Relations:
    """A: pose at t to pose at t + dt, every dt along the run."""
    return _consecutive(gt, sample_every(gt, params.dt))


def relations_S(gt: Trajectory, params: SParams = SParams()) -> Relations:
    """S: a pose every dt seconds, each related to the next."""
    return _consecutive(gt, sample_every(gt, params.dt))


def relations_M(gt: Trajectory, params: MParams = MParams()) -> Relations:
    """M: anchors each `distance` metres (Euclidean from the last anchor), consecutive ones
    related."""
    _positive("distance", params.distance)
    xy = np.ascontiguousarray(gt.poses[:, :2])
    return _consecutive(gt, distance_anchors(xy, params.distance))


def relations_SM(gt: Trajectory, params: SMParams = SMParams()) -> Relations:
    """SM: every pair (i < j) of poses sampled each dt lying more than min_distance apart.

    O(K^2) distance tests on the K sampled poses in a numba kernel (no Python loop): counts
    first, so the output is sized once and a too large request is refused before allocating.
    """
    _positive("min_distance", params.min_distance)
    idx = sample_every(gt, params.dt)
    xy = np.ascontiguousarray(gt.poses[idx, :2])
    counts = far_pair_counts(xy, params.min_distance)
    total = int(counts.sum())
    if total > params.max_relations:
        raise InputError(
            f"SM would make {total} relations, more than max_relations={params.max_relations}; "
            "raise dt or min_distance"
        )
    pi, pj = far_pairs_fill(xy, params.min_distance, counts)
    return _from_indices(gt, idx[pi], idx[pj])


def relations_L(gt: Trajectory, params: LParams = LParams()) -> Relations:
    """L: for each pose j that returns within `radius` of an earlier pose i after the path
    went more than `away` from i, one relation (i, j) to the nearest such i (the earliest
    on ties). A k-d tree finds the close pairs; a numba kernel the leave times."""
    from scipy.spatial import cKDTree

    _positive("radius", params.radius)
    _positive("away", params.away)
    n = len(gt)
    if n < 2:
        return _from_indices(gt, [], [])
    xy = np.ascontiguousarray(gt.poses[:, :2])
    pairs = cKDTree(xy).query_pairs(params.radius, output_type="ndarray")
    if pairs.shape[0] == 0:
        return _from_indices(gt, [], [])
    i, j = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)  # i < j
    limit = np.full(n, -1, dtype=np.int64)
    np.maximum.at(limit, i, j)
    leave = leave_index(xy, params.away, limit)
    valid = leave[i] < j
    i, j = i[valid], j[valid]
    dist = np.hypot(xy[j, 0] - xy[i, 0], xy[j, 1] - xy[i, 1])
    order = np.lexsort((i, dist, j))  # by j, then distance, then i
    i, j = i[order], j[order]
    first = np.ones(j.shape[0], dtype=bool)
    first[1:] = j[1:] != j[:-1]
    return _from_indices(gt, i[first], j[first])


def _random_pairs(
    n: int, count: int, rng: np.random.Generator
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """`count` pairs of distinct indices in [0, n), uniformly, each ordered i < j."""
    a = rng.integers(0, n, size=count)
    b = rng.integers(0, n - 1, size=count)
    b = b + (b >= a)  # uniform over the n - 1 indices other than a
    return np.minimum(a, b), np.maximum(a, b)


def b_sample_size(
    gt: Trajectory, est: Trajectory, rng: np.random.Generator, params: BParams = BParams()
) -> tuple[int, float, int]:
    """(N, s, evaluated pilots): N = ceil((z s / E)^2) before cap and floor, s the sample
    std (ddof 1, thesis) of the pilot relations' translational errors on the estimate."""
    _positive("z", params.z)
    _positive("margin", params.margin)
    if params.pilot < 2:
        raise InputError(f"pilot must be at least 2, got {params.pilot}")
    if len(gt) < 2:
        raise InputError("B relations need a ground truth of at least 2 poses")
    pilot = _from_indices(gt, *_random_pairs(len(gt), params.pilot, rng))
    err_t, _, ok = relation_errors(
        est.packed, pilot.t1, pilot.t2, pilot.delta, float(params.max_gap), TIME_TOL_S
    )
    used = int(ok.sum())
    if used < 2:
        raise InputError(
            f"the estimate covers too little of the ground truth: {used} of {params.pilot} "
            "pilot relations could be evaluated (check timestamps and max_gap)"
        )
    s = float(np.std(err_t[ok], ddof=1))
    return int(math.ceil((params.z * s / params.margin) ** 2)), s, used


def relations_B(
    gt: Trajectory, est: Trajectory, rng: np.random.Generator, params: BParams = BParams()
) -> Relations:
    """B: N random pairs of ground-truth poses, N from the pilot (`b_sample_size`), capped
    at max_relations with a `RelationsCapWarning`."""
    for name in ("max_relations", "min_relations"):
        if getattr(params, name) < 0:
            raise InputError(f"{name} must be >= 0, got {getattr(params, name)}")
    n_wanted, s, _ = b_sample_size(gt, est, rng, params)
    n_rel = max(n_wanted, params.min_relations)
    if n_rel > params.max_relations:
        warnings.warn(
            RelationsCapWarning(
                f"B: (z s / E)^2 = {n_wanted} relations (s = {s:.4g} m), capped at "
                f"max_relations = {params.max_relations}"
            ),
            stacklevel=2,
        )
        n_rel = params.max_relations
    return _from_indices(gt, *_random_pairs(len(gt), n_rel, rng))


KindParams = AParams | BParams | SMParams | LParams | MParams | SParams
DEFAULT_PARAMS: dict[str, type] = {
    "A": AParams,
    "B": BParams,
    "SM": SMParams,
    "L": LParams,
    "M": MParams,
    "S": SParams,
}


def generate_relations(
    kind: RelationKind,
    gt: Trajectory,
    params: KindParams | None = None,
    est: Trajectory | None = None,
    rng: np.random.Generator | None = None,
) -> Relations:
    """Relations of one kind; B needs the estimate and the run's random generator."""
    if kind not in DEFAULT_PARAMS:
        raise InputError(f"unknown relation kind {kind!r}, expected one of {list(DEFAULT_PARAMS)}")
    params = DEFAULT_PARAMS[kind]() if params is None else params
    if not isinstance(params, DEFAULT_PARAMS[kind]):
        raise TypeError(f"{kind} relations take {DEFAULT_PARAMS[kind].__name__}")
    if kind == "B":
        if est is None or rng is None:
            raise InputError("B relations need the estimate and a random generator")
        return relations_B(gt, est, rng, params)
    generator = {
        "A": relations_A,
        "S": relations_S,
        "M": relations_M,
        "SM": relations_SM,
        "L": relations_L,
    }[kind]
    return generator(gt, params)
