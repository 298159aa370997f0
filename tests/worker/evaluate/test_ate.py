"""ATE after SE(2) alignment: a rigidly moved copy, and evo's aligned APE as a cross-check."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.ate import absolute_trajectory_error, align_se2
from worker.evaluate.se2 import compose, inverse
from worker.evaluate.trajectory import Trajectory


def wander(rng, n=800):
    th = np.cumsum(rng.normal(0, 0.1, n))
    xy = np.cumsum(np.column_stack([np.cos(th), np.sin(th)]) * 0.08, axis=0)
    return Trajectory(np.arange(n) * 0.1, np.column_stack([xy, th]))


def test_rigidly_moved_copy_has_zero_error_and_the_inverse_alignment(rng):
    gt = wander(rng)
    T = np.array([12.0, -7.0, 2.5])  # est = T (+) gt: the SLAM map frame is elsewhere
    est = Trajectory(gt.t, compose(T, gt.poses))
    res = absolute_trajectory_error(gt, est)
    np.testing.assert_allclose(res.alignment[:2], inverse(T)[:2], atol=1e-9)
    assert math.cos(res.alignment[2] - inverse(T)[2]) == pytest.approx(1.0)
    assert res.summary()["translation"]["rmse"] == pytest.approx(0.0, abs=1e-9)
    assert res.summary()["rotation"]["max"] == pytest.approx(0.0, abs=1e-9)
    assert res.skipped == 0 and res.summary()["translation"]["n"] == len(gt)


def test_align_se2_hand_case():
    # dst is src rotated by +90 deg about the origin and shifted by (1, 0)
    src = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])
    dst = np.array([[1.0, 1.0], [0.0, 0.0], [1.0, -1.0]])
    np.testing.assert_allclose(align_se2(src, dst), [1.0, 0.0, math.pi / 2], atol=1e-12)


def test_matches_evo_aligned_ape(rng):
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    gt = wander(rng)
    noisy = gt.poses + np.column_stack([rng.normal(0, 0.2, (len(gt), 2)), np.zeros(len(gt))])
    est = Trajectory(gt.t, compose(np.array([3.0, 1.0, 0.4]), noisy))
    res = absolute_trajectory_error(gt, est).summary()

    def evo_traj(tr):
        xyz = np.column_stack([tr.poses[:, :2], np.zeros(len(tr))])
        h = tr.poses[:, 2] / 2
        quat = np.column_stack([np.cos(h), 0 * h, 0 * h, np.sin(h)])  # evo: w x y z
        return PoseTrajectory3D(xyz, quat, tr.t)

    ref, e = evo_traj(gt), evo_traj(est)
    e.align(ref, correct_scale=False)
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, e))
    stats = ape.get_all_statistics()
    assert res["translation"]["rmse"] == pytest.approx(stats["rmse"], rel=1e-6)
    assert res["translation"]["mean"] == pytest.approx(stats["mean"], rel=1e-6)
    assert res["translation"]["max"] == pytest.approx(stats["max"], rel=1e-6)
    assert res["translation"]["std"] == pytest.approx(stats["std"], rel=1e-6)


def test_unmatched_times_are_skipped_and_no_overlap_is_an_error(rng):
    gt = wander(rng, 100)
    half = Trajectory(gt.t[:50], gt.poses[:50])
    assert absolute_trajectory_error(gt, half).skipped == 50
    with pytest.raises(InputError, match="no ground-truth time"):
        absolute_trajectory_error(gt, Trajectory(gt.t + 100.0, gt.poses))
