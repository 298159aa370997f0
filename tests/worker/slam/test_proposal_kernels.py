"""The sampled improved proposal in a long featureless corridor: the fitted Gaussian spreads
along the corridor as the motion model does and not across it, by hand-derived variances."""

from __future__ import annotations

import math

import numpy as np

from worker.slam.match_kernels import match_config, prepare_beams, score_and_likelihood
from worker.slam.params import SlamParams
from worker.slam.proposal_kernels import fit_proposals, fit_proposals_parallel, sample_offsets
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

# 40 m long, 2 m wide; a 10 m laser at x = 20 sees neither end: only the two side walls
CORRIDOR = (0.0, 0.02, 40.0, 2.02)
LASER = Laser(range_max=10.0)
POSE = np.array([20.0, 1.02, 0.0])
STEPS = np.array([0.05, 0.05, 0.01])  # [m, m, rad] the grid's spacing


def _corridor_map():
    """The corridor's walls mapped from scans every 0.1 m along its axis, x = 8..32 (so that
    every wall cell within 10 m of POSE has hits, and their means are alike along the wall)."""
    slam = make_slam("odometry", LASER, SlamParams(linear_update=0, angular_update=0))
    for k, x in enumerate(np.arange(8.0, 32.0 + 1e-9, 0.1)):
        pose = np.array([x, 1.02, 0.0])
        slam.process(float(k), pose, box_scan(pose, LASER.angles, CORRIDOR, 10.0))
    return slam.maps


def _cfg():
    return match_config(
        res=0.05, usable_range=30.0, max_range=9.99, lskip=0, kernel=1, sigma=0.05,
        lsigma=0.075, lstep=0.05, astep=0.05, iterations=5, minimum_score=0.0,
    )  # fmt: skip


def test_the_sampling_grid_is_gmappings_and_holds_the_optimum():
    off = sample_offsets(0.1, 0.05, 0.01, 0.01)
    assert off.shape == (5 * 5 * 3, 3)
    assert np.any(np.all(off == 0.0, axis=1))  # the optimum itself
    assert np.allclose(np.unique(off[:, 0]), [-0.1, -0.05, 0.0, 0.05, 0.1])
    assert np.allclose(np.unique(off[:, 2]), [-0.01, 0.0, 0.01])
    assert sample_offsets(0.01, 0.01, 0.005, 0.005).shape == (27, 3)  # GMapping's defaults


def test_the_fitted_gaussian_spreads_along_a_featureless_corridor_and_not_across():
    maps = _corridor_map()
    cfg = _cfg()
    a = LASER.angles
    ranges = box_scan(POSE, a, CORRIDOR, 10.0)
    offsets = sample_offsets(0.1, 0.05, 0.01, 0.01)
    sigma_l, sigma_a = 0.05, 0.05  # [m], [rad] the motion model's deviations (isotropic)
    info = np.diag([1 / sigma_l**2, 1 / sigma_l**2, 1 / sigma_a**2])[None]
    mus, covs, log_eta = fit_proposals(
        maps.mean, maps.bits, maps.match_tables(), maps.tpx0, maps.tpy0, POSE[None], POSE[None],
        info,
        ranges, np.cos(a), np.sin(a), offsets, STEPS, 0, cfg,
    )  # fmt: skip
    mu, cov = mus[0], covs[0]
    # Along x the walls look the same every cell: the likelihood is flat and only the motion
    # model weighs the grid's five x values d = 0, +-0.05, +-0.1 m, by exp(-d^2 / 2 sigma^2)
    # = 1, e^-1/2, e^-2 (sigma = 0.05): variance 2 (0.05^2 e^-1/2 + 0.1^2 e^-2) / (1 + 2
    # e^-1/2 + 2 e^-2) = 0.00231 m^2 (std 0.048 m), symmetric about the optimum
    w1, w2 = math.exp(-0.5), math.exp(-2.0)
    along = 2 * (0.05**2 * w1 + 0.1**2 * w2) / (1 + 2 * w1 + 2 * w2)
    assert abs(along - 0.00231) < 1e-5
    assert abs(cov[0, 0] - along) < 0.02 * along
    assert abs(mu[0] - POSE[0]) < 0.01
    # Across, 0.05 m off moves every wall beam's end point a cell off its wall: each of the
    # ~450 beams that match loses 0.05^2 / lsigma = 1/30 of log-likelihood, e^-15 of the
    # weight: the grid's rows off the axis get none, the optimum's row all
    assert cov[1, 1] < 1e-3 * along and abs(mu[1] - POSE[1]) < 1e-3
    # Turning by 0.01 rad moves an end point d metres along the axis 0.01 d across its wall
    # (0.05 m, a cell, at 5 m): the heading is held by the scan too. Were it free, the motion
    # model (0.05 rad) would weigh the grid's three headings about alike, variance 2/3 0.01^2
    # = 6.7e-5 rad^2; it gets less than a tenth of that
    assert cov[2, 2] < 6.7e-6 and abs(mu[2]) < 1e-3
    # the normaliser: the optimum's likelihood times the sum of the grid's weights, all of it
    # on the optimum's row: 1 + 2 e^-1/2 + 2 e^-2 (the flat likelihood and the prior at 0)
    a_ = LASER.angles
    beams = prepare_beams(ranges, np.cos(a_), np.sin(a_), cfg)
    _, like0 = score_and_likelihood(
        maps.mean, maps.bits, maps.match_tables()[0], maps.tpx0, maps.tpy0, POSE, beams, cfg
    )
    assert abs(log_eta[0] - (like0 + math.log(1 + 2 * w1 + 2 * w2))) < 0.1


def test_a_wall_ahead_pins_the_axis_too():
    # the corridor closed 2 m ahead (x = 22): the ~106 beams within atan(1 / 2) = 26.6 deg of
    # the axis (0.5 deg apart) end on that wall, and 0.05 m along the axis costs each 1/30 of
    # log-likelihood: weight e^-1/2 e^-3.5 = 0.018 at +-0.05 m, none at +-0.1 m (out of the
    # window), variance 2 0.05^2 0.018 / 1.04 = 0.00009 m^2, a twenty-fifth of the open one's
    closed = (0.0, 0.0, 22.0, 2.0)
    slam = make_slam("odometry", LASER, SlamParams(linear_update=0, angular_update=0))
    for k, x in enumerate(np.arange(12.0, 21.0 + 1e-9, 0.1)):
        pose = np.array([x, 1.02, 0.0])
        slam.process(float(k), pose, box_scan(pose, LASER.angles, closed, 10.0))
    maps = slam.maps
    a = LASER.angles
    info = np.diag([1 / 0.05**2, 1 / 0.05**2, 1 / 0.05**2])[None]
    _, covs, _ = fit_proposals(
        maps.mean, maps.bits, maps.match_tables(), maps.tpx0, maps.tpy0, POSE[None], POSE[None],
        info,
        box_scan(POSE, a, closed, 10.0), np.cos(a), np.sin(a),
        sample_offsets(0.1, 0.05, 0.01, 0.01), STEPS, 0, _cfg(),
    )  # fmt: skip
    assert covs[0, 0, 0] < 0.1 * 0.00231 and covs[0, 1, 1] < 1e-5


def test_the_threaded_fit_gives_the_same_gaussians():
    maps = _corridor_map()
    a = LASER.angles
    modes = POSE + np.array([[0.0, 0.0, 0.0], [0.3, 0.01, 0.002], [-0.2, -0.02, -0.003]])
    priors = POSE + np.array([[0.05, 0.0, 0.0], [0.0, 0.0, 0.0], [-0.4, 0.0, 0.01]])
    info = np.repeat(np.diag([1 / 0.04**2, 1 / 0.01**2, 1 / 0.08**2])[None], 3, axis=0)
    tables = np.repeat(maps.match_tables()[:1], 3, axis=0)
    args = (
        maps.mean, maps.bits, tables, maps.tpx0, maps.tpy0, modes, priors, info,
        box_scan(POSE, a, CORRIDOR, 10.0), np.cos(a), np.sin(a),
        sample_offsets(0.1, 0.05, 0.01, 0.01), STEPS, 6, _cfg(),
    )  # fmt: skip
    serial, threaded = fit_proposals(*args), fit_proposals_parallel(*args)
    for s, t in zip(serial, threaded, strict=True):
        assert np.array_equal(s, t)
    # the third's prior lies 0.4 m back along the flat axis: the grid follows it there
    assert abs(serial[0][2, 0] - priors[2, 0]) < 0.03
