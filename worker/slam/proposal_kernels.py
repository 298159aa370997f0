"""The sampled improved proposal of Grisetti, Stachniss, Burgard (2007), Sec. IV, eqs. (9)-(11):
a Gaussian fitted around each particle's scan-match optimum, weighted by its normaliser.

Around the optimum x^ of particle i, K poses x_j on a fixed grid (offsets (K, 3)) each get
  tau_j = p(z | m_i, x_j) * p(x_j | x_i,t-1, u)
(the scan likelihood of match_kernels, beams as the matcher uses them, times the motion model's
Gaussian around the particle's noise-free odometry prediction); then
  mu  = sum tau_j x_j / eta,   Sigma = sum tau_j (x_j - mu)(x_j - mu)^T / eta,
  eta = sum tau_j   (the particle's weight factor, eq. (11); returned as log eta).
GMapping's ScanMatcher::likelihood fits the same moments on a grid of +-llsamplerange /
+-lasamplerange; its filter keeps the optimum and never draws from the Gaussian. Here the grid
may also move to its fitted mean (`shifts`), for a likelihood ridge along which the optimum is
one of many.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from worker.evaluate.se2_scalar import wrap
from worker.slam.match_cache_kernels import MAX_CACHED_KERNEL, new_cache
from worker.slam.match_kernels import _score, prepare_beams


def sample_offsets(lrange: float, lstep: float, arange: float, astep: float) -> np.ndarray:
    """(K, 3) [dx m, dy m, dtheta rad] the grid of GMapping's likelihood sampling: x and y in
    -lrange..+lrange by lstep, theta in -arange..+arange by astep (counts rounded, so that
    the grid is symmetric and holds the optimum itself)."""
    nl = int(round(lrange / lstep)) if lstep > 0 else 0
    na = int(round(arange / astep)) if astep > 0 else 0
    lin = lstep * np.arange(-nl, nl + 1)
    ang = astep * np.arange(-na, na + 1)
    gx, gy, gt = np.meshgrid(lin, lin, ang, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel(), gt.ravel()])


@njit(cache=True, nogil=True)
def _fit_particle(
    p, mus, covs, log_eta, mean, bits, tables, tpx0, tpy0, modes, priors, infos, beams, offsets,
    steps, shifts, cfg,
):  # fmt: skip
    """Fit particle p's Gaussian: mus[p] (3,), covs[p] (3, 3), log_eta[p].

    The grid starts centred on the optimum and moves, whole steps at a time, to its fitted
    mean while that lies half a step or more from its centre, at most `shifts` times: along a
    ridge of the likelihood (a corridor's axis) the optimum the matcher stopped at is one of
    many, and the Gaussian belongs where the motion model holds its weight.
    """
    m = beams.shape[0]
    k = offsets.shape[0]
    order = np.arange(m)
    dist2 = np.empty(m)
    none = np.empty(0)
    cache = new_cache(0, MAX_CACHED_KERNEL + 1)  # no cell cache: every pose scored whole
    log_tau = np.empty(k)
    w = np.empty(k)
    info = infos[p]
    centre = modes[p].copy()
    mo = np.zeros(3)
    total = 1.0
    top = 0.0
    for shift in range(shifts + 1):
        for j in range(k):
            x = centre[0] + offsets[j, 0]
            y = centre[1] + offsets[j, 1]
            t = centre[2] + offsets[j, 2]
            _, like, _ = _score(
                mean, bits, tables[p], tpx0, tpy0, x, y, t, beams, order, cfg, -np.inf, none,
                dist2, cache, 0,
            )  # fmt: skip
            d0 = x - priors[p, 0]
            d1 = y - priors[p, 1]
            d2 = wrap(t - priors[p, 2])
            q = (
                info[0, 0] * d0 * d0 + info[1, 1] * d1 * d1 + info[2, 2] * d2 * d2
                + 2.0 * (info[0, 1] * d0 * d1 + info[0, 2] * d0 * d2 + info[1, 2] * d1 * d2)
            )  # fmt: skip
            log_tau[j] = like - 0.5 * q
        top = log_tau.max()
        total = 0.0
        for j in range(k):
            w[j] = math.exp(log_tau[j] - top)
            total += w[j]
        # the mean offset (relative to the centre: no angle wraps inside the sums)
        for a in range(3):
            mo[a] = 0.0
            for j in range(k):
                mo[a] += w[j] * offsets[j, a]
            mo[a] /= total
        moved = False
        if shift < shifts:
            for a in range(3):
                n = round(mo[a] / steps[a]) if steps[a] > 0.0 else 0.0
                if n != 0.0:
                    moved = True
                    centre[a] += n * steps[a]
        if not moved:
            break
    cov = np.zeros((3, 3))
    for j in range(k):
        for a in range(3):
            da = offsets[j, a] - mo[a]
            for b in range(a, 3):
                cov[a, b] += w[j] * da * (offsets[j, b] - mo[b])
    for a in range(3):
        for b in range(a, 3):
            cov[a, b] /= total
            cov[b, a] = cov[a, b]
    mus[p, 0] = centre[0] + mo[0]
    mus[p, 1] = centre[1] + mo[1]
    mus[p, 2] = wrap(centre[2] + mo[2])
    covs[p] = cov
    log_eta[p] = top + math.log(total)


@njit(cache=True, nogil=True)
def fit_proposals(
    mean, bits, tables, tpx0, tpy0, modes, priors, infos, ranges, cos_a, sin_a, offsets, steps,
    shifts, cfg,
):  # fmt: skip
    """Every particle's proposal Gaussian around its optimum.

    modes (N, 3): the scan-match optima; priors (N, 3): the motion model's means (the noise-free
    odometry predictions), infos (N, 3, 3) its inverse covariances (map frame); offsets (K, 3)
    from `sample_offsets`, steps (3,) its spacing [m, m, rad]; shifts: how many times the grid
    may move to its fitted mean; cfg: match_kernels' (the fine matcher's beams and likelihood).
    Returns (mu (N, 3), Sigma (N, 3, 3), log eta (N,)).
    """
    beams = prepare_beams(ranges, cos_a, sin_a, cfg)
    n = modes.shape[0]
    mus = np.empty((n, 3))
    covs = np.empty((n, 3, 3))
    log_eta = np.empty(n)
    for p in range(n):
        _fit_particle(
            p, mus, covs, log_eta, mean, bits, tables, tpx0, tpy0, modes, priors, infos, beams,
            offsets, steps, shifts, cfg,
        )  # fmt: skip
    return mus, covs, log_eta


@njit(cache=True, nogil=True, parallel=True)
def fit_proposals_parallel(
    mean, bits, tables, tpx0, tpy0, modes, priors, infos, ranges, cos_a, sin_a, offsets, steps,
    shifts, cfg,
):  # fmt: skip
    """fit_proposals with the particles spread over numba's threads; the same result."""
    beams = prepare_beams(ranges, cos_a, sin_a, cfg)
    n = modes.shape[0]
    mus = np.empty((n, 3))
    covs = np.empty((n, 3, 3))
    log_eta = np.empty(n)
    for p in prange(n):
        _fit_particle(
            p, mus, covs, log_eta, mean, bits, tables, tpx0, tpy0, modes, priors, infos, beams,
            offsets, steps, shifts, cfg,
        )  # fmt: skip
    return mus, covs, log_eta
