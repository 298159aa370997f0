"""The scan matcher: a known pose recovered in a map built from closed-form scans, and score,
likelihood and hill climbing cross-checked against a plain Python transcription of GMapping's
ScanMatcher (every beam, every window cell, every candidate scored whole)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.slam.match_kernels import (
    exp_neg_upper,
    match_config,
    optimize,
    prepare_beams,
    score_and_likelihood,
)
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

BOX = (0.0, 0.0, 8.0, 5.0)


def _mapped():
    laser = Laser()
    slam = make_slam("odometry", laser, SlamParams(linear_update=0, angular_update=0))
    for k, pose in enumerate([(2.0, 2.0, 0.0), (5.0, 3.0, 2.0), (6.5, 1.0, 3.0), (1.5, 4.0, -1)]):
        slam.process(float(k), np.array(pose), box_scan(pose, laser.angles, BOX))
    return laser, slam


def _cfg(lskip: int = 0, kernel: int = 1, coarse_skip=0, coarse_levels=0) -> np.ndarray:
    return match_config(
        res=0.05, usable_range=30.0, max_range=29.99, lskip=lskip, kernel=kernel, sigma=0.05,
        lsigma=0.075, lstep=0.05, astep=0.05, iterations=5, minimum_score=0.0,
        coarse_skip=coarse_skip, coarse_levels=coarse_levels,
    )  # fmt: skip


def _beams(laser, ranges, cfg):
    a = laser.angles
    return prepare_beams(np.asarray(ranges, dtype=np.float64), np.cos(a), np.sin(a), cfg)


def _score(slam, laser, pose, ranges, cfg=None):
    cfg = _cfg() if cfg is None else cfg
    m = slam.maps
    beams = _beams(laser, ranges, cfg)
    return score_and_likelihood(
        m.mean, m.bits, m.match_tables()[0], m.tpx0, m.tpy0, np.asarray(pose, float), beams, cfg
    )


class _Reference:
    """GMapping's score and likelihood, cell by cell from the hits / visits planes."""

    def __init__(self, maps, laser, ranges, lskip, kernel=1):
        self.m, self.res, self.k = maps, 0.05, kernel
        a = laser.angles
        used = [i for i in range(lskip, len(ranges), lskip + 1) if 0 < ranges[i] <= 29.99]
        r = np.asarray(ranges)[used]
        back = self.res * math.sqrt(2.0)  # GMapping's free point: sqrt(2) cells back
        self.beams = [
            (ri * math.cos(ai), ri * math.sin(ai), (ri - back) * math.cos(ai),
             (ri - back) * math.sin(ai))
            for ri, ai in zip(r, a[used], strict=True)
        ]  # fmt: skip

    def cell(self, gx, gy):
        """(hits, visits, mean x, mean y) of cell (gx, gy); zeros when unknown."""
        m = self.m
        ty, tx = (gy >> 5) - m.tpy0, (gx >> 5) - m.tpx0
        th, tw = m.tables.shape[1:]
        if not (0 <= tx < tw and 0 <= ty < th) or m.tables[0, ty, tx] < 0:
            return 0.0, 0.0, 0.0, 0.0
        e, ly, lx = m.tables[0, ty, tx], gy & 31, gx & 31
        s = m.hslot[e]
        if s < 0:  # no beam ended in this patch
            return 0.0, float(m.visits[e, ly, lx]), 0.0, 0.0
        return (float(m.hits[s, ly, lx]), float(m.visits[e, ly, lx]),
                float(m.mean[s, ly, lx, 0]), float(m.mean[s, ly, lx, 1]))  # fmt: skip

    def score(self, pose):
        x, y, t = pose
        c, s = math.cos(t), math.sin(t)
        score = like = 0.0
        for px, py, fx, fy in self.beams:
            hx, hy = x + c * px - s * py, y + s * px + c * py
            ihx, ihy = math.floor(hx / self.res), math.floor(hy / self.res)
            ofx = math.floor((x + c * fx - s * fy) / self.res) - ihx
            ofy = math.floor((y + s * fx + c * fy) / self.res) - ihy
            best = None
            for gy in range(ihy - self.k, ihy + self.k + 1):
                for gx in range(ihx - self.k, ihx + self.k + 1):
                    h, v, mx, my = self.cell(gx, gy)
                    hf, vf, _, _ = self.cell(gx + ofx, gy + ofy)
                    occupied = v > 0 and h > 0.1 * v
                    free_before = not (vf > 0 and hf > 0 and hf >= 0.1 * vf)
                    if occupied and free_before:
                        d2 = (hx - gx * self.res - mx) ** 2 + (hy - gy * self.res - my) ** 2
                        best = d2 if best is None else min(best, d2)
            if best is None:
                like += -0.5 / 0.075
            else:
                score += math.exp(-best / 0.05)
                like -= best / 0.075
        return score, like

    def optimize(self, pose, coarse_skip=0, coarse_levels=0):
        """GMapping's ScanMatcher::optimize, every candidate scored whole; coarse to fine:
        the first coarse_levels step sizes on every (coarse_skip + 1)-th beam only."""
        ld, ad, refinement, pose = 0.05, 0.05, 0, list(pose)
        if coarse_skip and coarse_levels:
            every = self.beams
            self.beams = every[:: coarse_skip + 1]
            pose, _, ld, ad, refinement = self._climb(pose, ld, ad, 0, coarse_levels - 1)
            self.beams = every
            ld, ad, refinement = ld / 2, ad / 2, coarse_levels
        pose, cur, *_ = self._climb(pose, ld, ad, refinement, 5)
        return np.array(pose), cur

    def _climb(self, pose, ld, ad, refinement, last):
        cur, best = self.score(pose)[0], -1.0
        while True:
            if best >= cur:
                refinement, ld, ad = refinement + 1, ld / 2, ad / 2
            best, chosen = cur, pose
            for k, d in ((0, ld), (0, -ld), (1, -ld), (1, ld), (2, ad), (2, -ad)):
                cand = list(pose)
                cand[k] += d
                sc = self.score(cand)[0]
                if sc > cur:
                    cur, chosen = sc, cand
            pose = chosen
            if not (cur > best or refinement < last):
                return pose, cur, ld, ad, refinement


def test_score_peaks_at_the_true_pose():
    laser, slam = _mapped()
    truth = np.array([3.3, 2.2, 0.4])
    ranges = box_scan(truth, laser.angles, BOX)
    s_true, l_true = _score(slam, laser, truth, ranges)
    # nearly every beam matches within a few millimetres: score ~ number of beams
    assert s_true > 0.95 * len(ranges)
    assert l_true > -0.2 * len(ranges)  # a few corner beams find no match (-0.5 / lsigma)
    for off in ([0.1, 0, 0], [0, -0.1, 0], [0, 0, 0.05]):
        s_off, l_off = _score(slam, laser, truth + np.array(off), ranges)
        assert s_off < s_true and l_off < l_true


def test_score_and_likelihood_equal_the_reference():
    laser, slam = _mapped()
    truth = np.array([3.3, 2.2, 0.4])
    ranges = box_scan(truth, laser.angles, BOX)
    ranges[::50] = 0.0  # no reading
    ranges[7::50] = 35.0  # past maxRange
    for lskip in (0, 2):
        ref = _Reference(slam.maps, laser, ranges, lskip)
        for off in ([0.0, 0.0, 0.0], [0.03, -0.02, 0.01], [-0.2, 0.15, -0.3], [0.02, 0.0, 1.5]):
            pose = truth + np.array(off)
            got = _score(slam, laser, pose, ranges, _cfg(lskip))
            want = ref.score(pose)
            assert np.allclose(got, want, rtol=1e-9, atol=1e-9), (lskip, off, got, want)


def test_the_early_stop_bound_is_above_exp():
    # candidates are dropped on this bound: were it below exp anywhere, a winner could be lost
    x = np.concatenate([np.linspace(0.0, 3.0, 30001), np.geomspace(1e-12, 1e3, 2000)])
    upper = np.array([exp_neg_upper(v) for v in x])
    # up to rounding (an ulp, 1.1e-16): the stop test's slack of 1e-6 covers 1e5 beams of it
    assert np.all(upper >= np.exp(-x) - 2.3e-16)
    assert np.all(upper <= 1.0)
    # kernelSize 1: mu < 2 cells diagonally, x = mu^2 / sigma < 0.4; there it is tight
    near = x < 0.4
    assert np.max(upper[near] - np.exp(-x[near])) < 0.4**3 / 6 + 1e-15


def _assert_climbs_as_the_reference(lskip, kernel, offsets, coarse=(0, 0)):
    laser, slam = _mapped()
    m = slam.maps
    truth = np.array([3.3, 2.2, 0.4])
    ranges = box_scan(truth, laser.angles, BOX)
    cfg = _cfg(lskip, kernel, *coarse)
    ref = _Reference(m, laser, ranges, lskip, kernel)
    beams = _beams(laser, ranges, cfg)
    for off in offsets:
        start = truth + np.array(off)
        pose, score, like, s0, l0 = optimize(
            m.mean, m.bits, m.match_tables()[0], m.tpx0, m.tpy0, start, beams, cfg
        )
        want_pose, want_score = ref.optimize(start, *coarse)
        assert np.allclose(pose, want_pose, atol=1e-12) and np.isclose(score, want_score)
        assert np.allclose((score, like), ref.score(pose))
        assert np.allclose((s0, l0), ref.score(start))


@pytest.mark.parametrize("kernel, lskip", [(1, 2), (2, 4), (3, 6)])
def test_optimize_equals_plain_hill_climbing(kernel, lskip):
    # the kernel drops hopeless candidates early and reuses the cells of beams whose end
    # point stays in its cell (kernel <= 2); the reference scores all, afresh: same climb
    _assert_climbs_as_the_reference(lskip, kernel, ([0.12, -0.08, 0.04], [-0.07, 0.1, -0.05]))


@pytest.mark.parametrize("coarse_skip, coarse_levels", [(1, 2), (3, 4), (2, 5)])
def test_coarse_to_fine_equals_plain_hill_climbing(coarse_skip, coarse_levels):
    # the first step sizes climb on a subset of the beams, the rest on all of them: the same
    # climb as the reference's (a different one from the plain climb's for most of these
    # starts), and the score, likelihood and start figures are all-beam ones
    offsets = ([0.12, -0.08, 0.04], [-0.07, 0.1, -0.05], [0.3, 0.2, -0.1])
    _assert_climbs_as_the_reference(1, 1, offsets, (coarse_skip, coarse_levels))
    with pytest.raises(ValueError, match="coarse_levels"):
        _cfg(1, 1, 1, 6)  # more coarse step sizes than the climb has


def test_hill_climbing_recovers_the_pose():
    laser, slam = _mapped()
    m = slam.maps
    truth = np.array([3.3, 2.2, 0.4])
    ranges = box_scan(truth, laser.angles, BOX)
    cfg = _cfg()
    beams = _beams(laser, ranges, cfg)
    for off in ([0.12, -0.08, 0.04], [-0.1, 0.1, -0.05], [0.0, 0.0, 0.0]):
        start = truth + np.array(off)
        tables = m.match_tables()
        pose, score, *_ = optimize(m.mean, m.bits, tables[0], m.tpx0, m.tpy0, start, beams, cfg)
        assert np.hypot(*(pose[:2] - truth[:2])) < 0.025  # within half a map cell
        assert abs(pose[2] - truth[2]) < 0.01  # 3 cm at 3 m: the cell means limit it
        assert score >= _score(slam, laser, start, ranges)[0]
