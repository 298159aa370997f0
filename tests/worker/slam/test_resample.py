"""GMapping's weight normalisation, Neff and low-variance resampling, against hand values."""

from __future__ import annotations

import math

import numpy as np

from worker.slam.resample import normalized_weights, systematic_indices


def test_normalized_weights_and_neff_by_hand():
    # N = 2, ogain 3: gain 1/6, so a log-likelihood gap of 6 ln 2 is a weight ratio of 2
    w, neff = normalized_weights(np.array([0.0, -6 * math.log(2)]), 3.0)
    assert np.allclose(w, [2 / 3, 1 / 3])
    assert math.isclose(neff, 1 / (4 / 9 + 1 / 9))
    # huge log-likelihoods do not overflow: only differences count
    w, neff = normalized_weights(np.array([-1e6, -1e6, -1e6]), 3.0)
    assert np.allclose(w, 1 / 3) and math.isclose(neff, 3.0)


def test_systematic_resampling_keeps_proportions(rng):
    # weights 1/2, 1/2, 0, 0: whatever the draw, pointers (u + k) / 4 pick 0, 0, 1, 1
    for _ in range(20):
        assert systematic_indices(np.array([0.5, 0.5, 0.0, 0.0]), rng).tolist() == [0, 0, 1, 1]
    # 1/4 each: every particle exactly once
    assert systematic_indices(np.full(4, 0.25), rng).tolist() == [0, 1, 2, 3]
    # a particle of weight 0.6 among 10 gets 6 copies (low variance: floor or ceil of N w)
    w = np.array([0.6] + [0.4 / 9] * 9)
    idx = systematic_indices(w, rng)
    assert np.count_nonzero(idx == 0) == 6 and len(idx) == 10
