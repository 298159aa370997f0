"""Particle weights and resampling as GMapping does them (normalize, Neff, uniform resampler)."""

from __future__ import annotations

import numpy as np


def normalized_weights(log_weights: np.ndarray, ogain: float) -> tuple[np.ndarray, float]:
    """(N,) accumulated log-likelihoods -> (normalised weights (N,), Neff).

    GMapping's GridSlamProcessor::normalize: w_i = exp(gain (l_i - max l)) with
    gain = 1 / (ogain N), which flattens the very peaked raw likelihoods; Neff = 1 / sum w_i^2.
    """
    n = log_weights.shape[0]
    gain = 1.0 / (ogain * n)
    w = np.exp(gain * (log_weights - log_weights.max()))
    w /= w.sum()
    return w, float(1.0 / np.sum(w * w))


def systematic_indices(weights: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) normalised weights -> (N,) int64 indices of the particles kept (sorted).

    Low-variance resampling with one uniform draw (GMapping's uniform_resampler): N pointers
    spaced 1/N apart, starting at u ~ U[0, 1/N), each picks the particle whose cumulative
    weight interval holds it.
    """
    n = weights.shape[0]
    pointers = (rng.random() + np.arange(n)) / n
    cum = np.cumsum(weights)
    cum[-1] = 1.0  # guard against rounding: the last pointer must find a particle
    return np.searchsorted(cum, pointers, side="right").astype(np.int64)
