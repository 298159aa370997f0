"""The reachable cells seen free (the coverage's numerator), found in chunks of int32 cell
indices, equal a cell-by-cell computation in plain floats: each reachable world cell's centre
taken into the map frame, floored to a map cell, free when that cell is known and at most the
threshold. Small chunks and bands make the chunk and band edges fall inside the plan."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from worker.evaluate import coverage
from worker.evaluate.coverage import ReachCells, seen_free


def by_hand(reach, res, origin, prob, mres, morigin, thresh, T):
    out = np.zeros_like(reach)
    c, s = math.cos(T[2]), math.sin(T[2])
    for iy, ix in zip(*np.nonzero(reach), strict=True):
        xw = float(origin[0]) + (int(ix) + 0.5) * res - float(T[0])
        yw = float(origin[1]) + (int(iy) + 0.5) * res - float(T[1])
        mx = math.floor((c * xw + s * yw - float(morigin[0])) / mres)
        my = math.floor((-s * xw + c * yw - float(morigin[1])) / mres)
        if 0 <= mx < prob.shape[1] and 0 <= my < prob.shape[0]:
            p = float(prob[my, mx])
            out[iy, ix] = not math.isnan(p) and p <= thresh
    return out


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    chunk=st.integers(1, 40),
    band=st.integers(1, 9),
    theta=st.floats(-math.pi, math.pi),
    shift=st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0)),
    mres=st.sampled_from([0.05, 0.1, 0.025]),
)
def test_chunked_seen_free_equals_cell_by_cell(seed, chunk, band, theta, shift, mres):
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(1, 30)), int(rng.integers(1, 30))
    reach = rng.random((h, w)) < rng.uniform(0.0, 1.0)
    prob = rng.uniform(0.0, 1.0, size=(int(rng.integers(1, 40)), int(rng.integers(1, 40))))
    prob[rng.random(prob.shape) < 0.3] = np.nan
    prob = prob.astype(np.float32)
    origin, morigin = np.array([-0.3, 0.2]), np.array([-0.5, -0.4])
    T = np.array([shift[0], shift[1], theta])
    args = (prob, mres, morigin, 0.25, T)
    want = by_hand(reach, 0.05, origin, *args)
    old = coverage._CHUNK, coverage._BAND
    coverage._CHUNK, coverage._BAND = chunk, band
    try:
        cells = ReachCells(reach, 0.05, origin)
        got = seen_free(reach, 0.05, origin, *args)
        held = seen_free(reach, 0.05, origin, *args, cells)
        cov = cells.coverage(*args)
    finally:
        coverage._CHUNK, coverage._BAND = old
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(held, want)
    assert cells.iy.dtype == np.int32
    n = np.count_nonzero(reach)
    assert cov == (np.count_nonzero(want) / n if n else 0.0)
