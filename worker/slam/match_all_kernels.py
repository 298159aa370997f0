"""The improved proposal for every particle at once (GMapping GridSlamProcessor::scanMatch):
each particle's scan match (`match_kernels.optimize`) in turn, or spread over numba's threads."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from worker.slam.match_kernels import C_MINIMUM_SCORE, optimize, prepare_beams


@njit(cache=True, nogil=True)
def _match_particle(p, out, scores, likes, mean, bits, tables, tpx0, tpy0, poses, beams, cfg):
    """Improved proposal of particle p: write its pose, score and log-likelihood at [p]."""
    refined, sc, like, _, start_like = optimize(
        mean, bits, tables[p], tpx0, tpy0, poses[p], beams, cfg
    )
    if sc > cfg[C_MINIMUM_SCORE]:
        out[p] = refined
        likes[p] = like
    else:
        out[p] = poses[p]
        likes[p] = start_like
    scores[p] = sc


@njit(cache=True, nogil=True)
def scan_match_all(mean, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg):
    """The improved proposal for every particle (GMapping GridSlamProcessor::scanMatch).

    Each particle's pose is refined against its own map, kept as drawn from the motion model
    when the match score is not above minimum_score. Returns (poses (N, 3), score (N,),
    log-likelihood (N,)) with the likelihood at the final pose. cfg: see CFG_FIELDS.
    """
    beams = prepare_beams(ranges, cos_a, sin_a, cfg)
    n = poses.shape[0]
    out = np.empty_like(poses)
    scores = np.zeros(n)
    likes = np.zeros(n)
    for p in range(n):
        _match_particle(p, out, scores, likes, mean, bits, tables, tpx0, tpy0, poses, beams, cfg)
    return out, scores, likes


@njit(cache=True, nogil=True, parallel=True)
def scan_match_all_parallel(mean, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg):
    """scan_match_all with the particles spread over numba's threads; the same result (each
    particle reads the shared maps and writes only its own row)."""
    beams = prepare_beams(ranges, cos_a, sin_a, cfg)
    n = poses.shape[0]
    out = np.empty_like(poses)
    scores = np.zeros(n)
    likes = np.zeros(n)
    for p in prange(n):
        _match_particle(p, out, scores, likes, mean, bits, tables, tpx0, tpy0, poses, beams, cfg)
    return out, scores, likes
