"""The ridge of the map score's walls, computed band by band, equals the whole-map
computation it replaced (kept here as the reference, as it was before issue 52), cell for
cell, on random maps, smoothing widths and band heights, through both wall extractions."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import ndimage

from worker.evaluate import map_score_kernels as k

_ACROSS = ((0, 1), (1, 1), (1, 0), (1, -1))


def whole_ridge(p, cand, sigma_cells, concave=False):
    """`_ridge` on the whole map at once (before issue 52)."""
    if not cand.any():
        return cand

    def g(order):
        return ndimage.gaussian_filter(p, sigma_cells, order=order, mode="constant")

    if concave:
        s = g((0, 0))
        q = np.pad(s, 1)
        hyy = q[2:, 1:-1] - 2.0 * s + q[:-2, 1:-1]
        hxx = q[1:-1, 2:] - 2.0 * s + q[1:-1, :-2]
        hxy = 0.25 * (q[2:, 2:] - q[2:, :-2] - q[:-2, 2:] + q[:-2, :-2])
    else:
        s, hyy, hxx, hxy = g((0, 0)), g((2, 0)), g((0, 2)), g((1, 1))
    half_gap = np.hypot(0.5 * (hxx - hyy), hxy)
    lam_min = 0.5 * (hxx + hyy) - half_gap
    line = 2.0 * half_gap > 0.5 * np.abs(lam_min)
    normal = 0.5 * np.arctan2(2.0 * hxy, hxx - hyy) + 0.5 * np.pi
    bins = np.round(normal / (0.25 * np.pi)).astype(np.int64) % 4
    padded = np.pad(np.where(cand, s, -np.inf), 1, constant_values=-np.inf)
    h, w = p.shape
    keep = np.zeros_like(cand)
    eps = 1e-9 * max(float(s.max()), 1.0)
    for b, (dy, dx) in enumerate(_ACROSS):
        fwd = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
        bwd = padded[1 - dy : 1 - dy + h, 1 - dx : 1 - dx + w]
        keep |= (bins == b) & (s >= fwd - eps) & (s >= bwd - eps)
    if concave:
        lam_max = lam_min + 2.0 * half_gap
        keep &= (lam_min < -eps) & (lam_min + lam_max < 0.0)
        peak = lam_max < -eps
        for dy, dx in _ACROSS:
            fwd = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            bwd = padded[1 - dy : 1 - dy + h, 1 - dx : 1 - dx + w]
            peak &= (s >= fwd - eps) & (s >= bwd - eps)
        return cand & np.where(line, keep, peak)
    return cand & (keep | ~line)


def _map(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """End-point counts on a few noisy walls and posts, and a hit ratio with unknown cells."""
    rng = np.random.default_rng(seed)
    h, w = int(rng.integers(1, 70)), int(rng.integers(1, 50))
    hits = np.zeros((h, w), dtype=np.float32)
    for _ in range(int(rng.integers(0, 6))):
        if rng.random() < 0.5:  # a wall along a row, its end points spread across it
            y, x0 = int(rng.integers(0, h)), int(rng.integers(0, w))
            for x in range(x0, min(w, x0 + int(rng.integers(1, 40)))):
                yy = int(np.clip(y + rng.normal(0.0, 1.0), 0, h - 1))
                hits[yy, x] += rng.integers(1, 5)
        else:  # a post
            hits[int(rng.integers(0, h)), int(rng.integers(0, w))] += rng.integers(1, 9)
    hits[rng.random((h, w)) < 0.02] += 1.0  # stray end points
    prob = rng.random((h, w)).astype(np.float32)
    prob[rng.random((h, w)) < 0.3] = np.nan
    return hits, prob


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 100_000),
    rows=st.integers(1, 12),
    sigma=st.sampled_from([0.4, 1.0, 1.5, 2.2]),
)
def test_banded_walls_equal_the_whole_map(seed, rows, sigma):
    hits, prob = _map(seed)
    h64 = np.asarray(hits, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        solid = np.nan_to_num(np.asarray(prob, dtype=np.float64), nan=0.0) > 0.05
    want_density = whole_ridge(h64, h64 > 0.0, sigma, concave=True) & solid
    p = np.nan_to_num(np.asarray(prob, dtype=np.float64), nan=0.0)
    want_ridge = whole_ridge(p, p > 0.25, sigma)
    old = k._ROWS
    k._ROWS = rows
    try:
        got_density = k.density_walls(hits, prob, sigma, 0.05)
        got_ridge = k.ridge_walls(prob, 0.25, sigma)
    finally:
        k._ROWS = old
    np.testing.assert_array_equal(got_density, want_density)
    np.testing.assert_array_equal(got_ridge, want_ridge)
