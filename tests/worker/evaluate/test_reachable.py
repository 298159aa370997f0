"""The reachable free cells (coverage's denominator) from the bounded distance transform equal
those of scipy's whole-plan exact Euclidean transform (the code they replace, kept here as the
reference), on random plans, robot sizes and resolutions, including starts inside a wall."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from worker.evaluate import coverage
from worker.evaluate.coverage import reachable_free

_FOUR = ndimage.generate_binary_structure(2, 1)


def scipy_reachable(occ, resolution, start_cell, half_side, clearance=None):
    """reachable_free as written with scipy's whole-plan transforms (before issue 52)."""
    clearance = half_side if clearance is None else clearance
    free = ~occ
    dist = ndimage.distance_transform_edt(np.pad(free, 1, constant_values=False))[1:-1, 1:-1]
    centre_ok = (dist - 0.5) * resolution > clearance
    labels, _ = ndimage.label(centre_ok, structure=_FOUR)
    ix, iy = start_cell
    lab = labels[iy, ix] if (0 <= iy < occ.shape[0] and 0 <= ix < occ.shape[1]) else 0
    if lab == 0:
        if not centre_ok.any():
            return np.zeros_like(occ)
        _, (ny, nx) = ndimage.distance_transform_edt(~centre_ok, return_indices=True)
        lab = labels[ny[iy, ix], nx[iy, ix]]
    reach = labels == lab
    to_reach = ndimage.distance_transform_edt(~reach) * resolution
    return free & (to_reach <= half_side * math.sqrt(2.0) + resolution)


def _plan(seed: int, h: int, w: int) -> np.ndarray:
    """Walls with doors and scattered obstacles (pillars, furniture)."""
    rng = np.random.default_rng(seed)
    occ = rng.random((h, w)) < 0.01
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    for _ in range(rng.integers(1, 5)):
        if rng.random() < 0.5:
            y = rng.integers(1, h - 1)
            occ[y, :] = True
            gap = rng.integers(1, w - 12)
            occ[y, gap : gap + rng.integers(3, 12)] = False
        else:
            x = rng.integers(1, w - 1)
            occ[:, x] = True
            gap = rng.integers(1, h - 12)
            occ[gap : gap + rng.integers(3, 12), x] = False
    return occ


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10**6),
    h=st.integers(20, 90),
    w=st.integers(20, 90),
    resolution=st.sampled_from([0.05, 0.1, 0.025, 0.073]),
    half_side=st.floats(0.05, 0.45),
    clearance=st.one_of(st.none(), st.floats(0.0, 0.5)),
    start=st.tuples(st.floats(0, 0.999), st.floats(0, 0.999)),  # where in the plan
)
def test_the_bounded_transform_gives_scipys_cells(
    seed, h, w, resolution, half_side, clearance, start
):
    occ = _plan(seed, h, w)
    start = (int(start[0] * w), int(start[1] * h))  # (ix, iy), in a wall at times
    got = reachable_free(occ, resolution, start, half_side, clearance)
    want = scipy_reachable(occ, resolution, start, half_side, clearance)
    assert got.dtype == want.dtype == np.bool_
    np.testing.assert_array_equal(got, want)


def test_bands_join_exactly(monkeypatch):
    """A plan many bands tall (the kernel is called band by band) still matches."""
    monkeypatch.setattr(coverage, "_BAND", 7)
    occ = _plan(3, 200, 60)
    for start in [(30, 100), (1, 1), (59, 199)]:
        np.testing.assert_array_equal(
            reachable_free(occ, 0.05, start, 0.2), scipy_reachable(occ, 0.05, start, 0.2)
        )
