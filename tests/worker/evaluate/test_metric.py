"""The relations metric: Kuemmerle's Fig. 2 case by hand, evo on the same pairs, summary."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from worker.evaluate.metric import evaluate_relations
from worker.evaluate.relations import Relations, relations_A, relations_B
from worker.evaluate.se2 import compose, interpolate, relative
from worker.evaluate.trajectory import Trajectory

V = 1.0  # [m/s]


def straight_with_rotation_error(k: int, eps: float, n: int = 1001):
    """Ground truth along +x at V m/s, 10 Hz; the estimate turns by eps at sample k and is
    otherwise exact (the situation of Kuemmerle et al. 2009, Fig. 2)."""
    t = np.arange(n) * 0.1
    gt = Trajectory(t, np.column_stack([V * t, np.zeros(n), np.zeros(n)]))
    xk = V * t[k]
    after = np.maximum(V * t - xk, 0.0)
    est = np.column_stack(
        [
            np.where(t > t[k], xk + after * math.cos(eps), V * t),
            np.where(t > t[k], after * math.sin(eps), 0.0),
            np.where(t > t[k], eps, 0.0),
        ]
    )
    return gt, Trajectory(t, est)


def test_single_early_rotation_error_is_one_large_error_kummerle_fig2():
    eps = 0.05
    gt, est = straight_with_rotation_error(k=10, eps=eps)  # error at t = 1 s, x = 1 m

    def gt_rel(a, b):
        p, _ = gt.poses_at([a, b])
        return Relations([a], [b], relative(p[0], p[1])[None])

    # a relation across the error: |d.xy - d*.xy| = 2 L sin(eps/2), L the length after it
    across = evaluate_relations(gt_rel(0.0, 100.0), est)
    assert across.translation[0] == pytest.approx(2 * 99.0 * math.sin(eps / 2), rel=1e-9)
    assert across.rotation[0] == pytest.approx(eps, rel=1e-9)
    # a relation after the error sees nothing, wherever it lies
    after = evaluate_relations(gt_rel(50.0, 90.0), est)
    assert after.translation[0] == pytest.approx(0.0, abs=1e-9)
    assert after.rotation[0] == pytest.approx(0.0, abs=1e-12)
    # A relations: only the one 0.5 s relation spanning t = 1 s catches it, and barely
    a = evaluate_relations(relations_A(gt), est)
    big = np.nonzero(a.rotation > 1e-9)[0]
    assert big.tolist() == [2]  # 1.0 s -> 1.5 s, the one relation spanning the turn
    assert a.t1[2] == pytest.approx(1.0)
    assert a.rotation[2] == pytest.approx(eps)
    assert a.translation[2] == pytest.approx(2 * 0.5 * math.sin(eps / 2), rel=1e-9)
    assert a.summary()["translation"]["mean"] < across.translation[0] / 1000


def test_B_errors_grow_with_how_much_path_follows_the_error():
    eps = 0.02
    gt, est = straight_with_rotation_error(k=300, eps=eps)  # turn at t = 30 s
    errs = evaluate_relations(relations_B(gt, est, np.random.default_rng(0)), est)
    spans = (errs.t1 <= 30.0) & (errs.t2 > 30.0)
    assert spans.sum() > 10 and (~spans).sum() > 10
    np.testing.assert_allclose(errs.translation[~spans], 0.0, atol=1e-9)
    np.testing.assert_allclose(errs.rotation[spans], eps, rtol=1e-9)
    length = V * errs.t2[spans] - 30.0
    np.testing.assert_allclose(errs.translation[spans], 2 * length * math.sin(eps / 2), rtol=1e-9)


def noisy_pair(rng, n=3000):
    th = np.cumsum(rng.normal(0, 0.1, n))
    xy = np.cumsum(np.column_stack([np.cos(th), np.sin(th)]) * 0.08, axis=0)
    gt = Trajectory(np.arange(n) * 0.1, np.column_stack([xy, th]))
    drift = compose(np.zeros(3), np.column_stack([rng.normal(0, 0.02, (n, 2)), th]))
    est = Trajectory(gt.t, drift + np.column_stack([xy, np.cumsum(rng.normal(0, 2e-3, n))]))
    return gt, est


def evo_errors(gt_pairs: np.ndarray, est_pairs: np.ndarray):
    """evo's RPE (translation_part, rotation_angle_rad) on poses interleaved so that evo's
    consecutive pairs (2k, 2k+1) are our relations; (2k+1, 2k+2) are dropped."""
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D

    def path(p2d):
        m = np.zeros((p2d.shape[0], 4, 4))
        c, s = np.cos(p2d[:, 2]), np.sin(p2d[:, 2])
        m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = c, -s, s, c
        m[:, 0, 3], m[:, 1, 3], m[:, 2, 2], m[:, 3, 3] = p2d[:, 0], p2d[:, 1], 1.0, 1.0
        return PosePath3D(poses_se3=list(m))

    data = (path(gt_pairs), path(est_pairs))
    out = []
    for rel in (metrics.PoseRelation.translation_part, metrics.PoseRelation.rotation_angle_rad):
        rpe = metrics.RPE(rel, delta=1, delta_unit=metrics.Unit.frames, all_pairs=False)
        rpe.process_data(data)
        out.append(np.asarray(rpe.error)[::2])
    return out


def interleave(a, b):
    out = np.empty((2 * a.shape[0], 3))
    out[0::2], out[1::2] = a, b
    return out


def test_matches_evo_rpe_on_the_same_pairs(rng):
    gt, est = noisy_pair(rng)
    rel = relations_B(gt, est, np.random.default_rng(3))
    assert len(rel) > 200
    errs = evaluate_relations(rel, est)
    assert errs.evaluated.all()
    g1, _ = gt.poses_at(rel.t1)
    g2, _ = gt.poses_at(rel.t2)
    e1, _ = est.poses_at(rel.t1)
    e2, _ = est.poses_at(rel.t2)
    evo_t, evo_r = evo_errors(interleave(g1, g2), interleave(e1, e2))
    np.testing.assert_allclose(errs.translation, evo_t, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(errs.rotation, evo_r, rtol=1e-7, atol=1e-7)
    s = errs.summary()["translation"]
    assert s["mean"] == pytest.approx(np.mean(evo_t), rel=1e-9)
    assert s["std"] == pytest.approx(np.std(evo_t), rel=1e-9)  # population std, as evo
    assert s["max"] == pytest.approx(np.max(evo_t), rel=1e-9)
    assert s["mean_squared"] == pytest.approx(np.mean(evo_t**2), rel=1e-9)


def test_between_samples_the_estimate_is_interpolated(rng):
    gt, est = noisy_pair(rng, 500)
    t1 = rng.uniform(1.0, 20.0, 300)
    t2 = rng.uniform(20.0, 49.0, 300)
    delta = rng.normal(0, 1, (300, 3))
    errs = evaluate_relations(Relations(t1, t2, delta), est)

    def at(q):  # independent lookup: neighbours by searchsorted, numpy SE(2) interpolation
        i = np.searchsorted(est.t, q, side="right") - 1
        a = (q - est.t[i]) / (est.t[i + 1] - est.t[i])
        return interpolate(est.poses[i], est.poses[i + 1], a)

    d = relative(at(t1), at(t2))
    np.testing.assert_allclose(errs.translation, np.hypot(*(d - delta)[:, :2].T), atol=1e-9)
    dth = np.abs(np.angle(np.exp(1j * (d[:, 2] - delta[:, 2]))))
    np.testing.assert_allclose(errs.rotation, dth, atol=1e-9)


def test_unevaluable_relations_are_skipped_and_counted():
    t = np.concatenate([np.arange(0, 10) * 0.1, 5.0 + np.arange(0, 10) * 0.1])  # 4 s hole
    est = Trajectory(t, np.column_stack([t, 0 * t, 0 * t]))
    rel = Relations(
        [0.1, 0.2, 3.0, -1.0, 5.1],
        [0.5, 5.5, 5.2, 0.3, 20.0],
        [[0.4, 0, 0], [5.3, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]],
    )
    errs = evaluate_relations(rel, est)
    np.testing.assert_array_equal(errs.evaluated, [True, True, False, False, False])
    s = errs.summary()
    assert s["skipped"] == 3
    assert s["translation"]["n"] == 2 and s["rotation"]["n"] == 2
    assert s["translation"]["max"] == pytest.approx(0.0, abs=1e-12)


def test_summary_shape_and_no_nan_when_nothing_is_evaluated():
    est = Trajectory(np.arange(5) * 0.1, np.zeros((5, 3)))
    s = evaluate_relations(Relations([100.0], [200.0], [[1.0, 0, 0]]), est).summary()
    assert list(s) == ["translation", "rotation", "skipped"]
    keys = ["mean", "std", "min", "max", "n", "mean_squared", "ci95"]
    assert list(s["translation"]) == keys and list(s["rotation"]) == keys
    assert s["translation"]["n"] == 0 and s["translation"]["mean"] is None and s["skipped"] == 1
    json.dumps(s, allow_nan=False)
    empty = evaluate_relations(Relations([], [], np.zeros((0, 3))), est).summary()
    assert empty["skipped"] == 0 and empty["rotation"]["std"] is None


def test_summary_by_hand():
    est = Trajectory(np.array([0.0, 1.0, 2.0]), np.zeros((3, 3)))
    # true motions 3 m and 4 m, estimate 0: errors 3 and 4; rotations 0.1 and 0.3
    rel = Relations([0.0, 0.0], [1.0, 2.0], [[3.0, 0, 0.1], [0, 4.0, -0.3]])
    s = evaluate_relations(rel, est).summary()
    # 95 % half-width of the mean of 3 and 4: t(0.975, 1) = 12.706, s = 0.7071, / sqrt(2)
    assert s["translation"].pop("ci95") == pytest.approx(12.706 * 0.5, abs=1e-3)
    assert s["translation"] == pytest.approx(
        {"mean": 3.5, "std": 0.5, "min": 3.0, "max": 4.0, "n": 2, "mean_squared": 12.5}
    )
    assert s["rotation"]["mean"] == pytest.approx(0.2)
    assert s["rotation"]["mean_squared"] == pytest.approx(0.05)
