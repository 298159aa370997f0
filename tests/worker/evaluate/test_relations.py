"""Relation generators A, S, M, SM, L, B against hand-derived cases and brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.relations import (
    AParams,
    BParams,
    LParams,
    MParams,
    Relations,
    RelationsCapWarning,
    SMParams,
    SParams,
    b_sample_size,
    generate_relations,
    relations_A,
    relations_B,
    relations_L,
    relations_M,
    relations_S,
    relations_SM,
)
from worker.evaluate.se2 import relative
from worker.evaluate.trajectory import Trajectory


def line(n=101, dt=0.1, v=1.0, t0=0.0):
    """Straight run along +x at v m/s, sampled every dt (times as a simulator counts them)."""
    t = t0 + np.arange(n) * dt
    return Trajectory(t, np.column_stack([v * (t - t0), np.zeros(n), np.zeros(n)]))


def wander(rng, n=600):
    th = np.cumsum(rng.normal(0, 0.15, n))
    xy = np.cumsum(np.column_stack([np.cos(th), np.sin(th)]) * 0.08, axis=0)
    return Trajectory(np.arange(n) * 0.1, np.column_stack([xy, th]))


def check_deltas(gt: Trajectory, rel: Relations):
    """Every relation's delta is inv(X*(t1)) X*(t2) of ground-truth samples at t1, t2."""
    i = np.searchsorted(gt.t, rel.t1)
    j = np.searchsorted(gt.t, rel.t2)
    np.testing.assert_array_equal(gt.t[i], rel.t1)
    np.testing.assert_array_equal(gt.t[j], rel.t2)
    np.testing.assert_allclose(rel.delta, relative(gt.poses[i], gt.poses[j]), atol=1e-12)


def test_A_every_half_second_on_a_straight_line():
    gt = line(101)  # 10 s at 1 m/s
    rel = relations_A(gt)
    assert len(rel) == 20
    np.testing.assert_allclose(rel.t2 - rel.t1, 0.5, atol=1e-9)
    np.testing.assert_allclose(rel.delta, [[0.5, 0.0, 0.0]] * 20, atol=1e-9)
    np.testing.assert_allclose(rel.t1[:3], [0.0, 0.5, 1.0], atol=1e-9)
    check_deltas(gt, rel)


def test_S_every_x_seconds_and_offset_start():
    gt = line(101, t0=1234.5)
    rel = relations_S(gt, SParams(dt=2.0))
    assert len(rel) == 5
    np.testing.assert_allclose(rel.t1, 1234.5 + np.arange(5) * 2.0, atol=1e-9)
    np.testing.assert_allclose(rel.delta[:, 0], 2.0, atol=1e-9)


def test_M_uses_euclidean_distance_from_the_last_anchor():
    # out 1.5 m and back: 3 m travelled but never 2 m from the start -> no M relation
    t = np.arange(31) * 0.1
    x = np.concatenate([np.linspace(0, 1.5, 16), np.linspace(1.4, 0.0, 15)])
    back = Trajectory(t, np.column_stack([x, np.zeros(31), np.zeros(31)]))
    assert len(relations_M(back, MParams(distance=2.0))) == 0
    rel = relations_M(line(101), MParams(distance=2.0))  # 10 m straight
    np.testing.assert_allclose(rel.delta[:, 0], 2.0, atol=1e-9)
    assert len(rel) == 5


def test_SM_matches_brute_force(rng):
    gt = wander(rng, 900)
    p = SMParams(dt=2.0, min_distance=1.5)
    rel = relations_SM(gt, p)
    idx = np.arange(0, 900, 20)  # samples every 2 s at 10 Hz
    xy = gt.poses[idx, :2]
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    ii, jj = np.nonzero(np.triu(d > 1.5, k=1))
    assert len(rel) == len(ii) > 0
    np.testing.assert_array_equal(rel.t1, gt.t[idx[ii]])
    np.testing.assert_array_equal(rel.t2, gt.t[idx[jj]])
    check_deltas(gt, rel)


def test_SM_refuses_too_many_relations(rng):
    with pytest.raises(InputError, match="raise dt or min_distance"):
        relations_SM(wander(rng, 900), SMParams(dt=0.1, min_distance=0.1, max_relations=1000))


def brute_force_L(xy, radius, away):
    n = xy.shape[0]
    out = []
    for j in range(n):
        best = None
        for i in range(j):
            dij = math.dist(xy[i], xy[j])
            if dij > radius:
                continue
            left = any(math.dist(xy[k], xy[i]) > away for k in range(i + 1, j))
            if left and (best is None or dij < best[0]):
                best = (dij, i)
        if best is not None:
            out.append((best[1], j))
    return out


def test_L_on_a_square_loop_matches_brute_force():
    # a 2 m square driven twice, 0.1 m steps with a little jitter so ties are rare
    side = np.linspace(0, 2, 21)[:-1]
    sq = np.concatenate(
        [
            np.column_stack([side, 0 * side]),
            np.column_stack([2 + 0 * side, side]),
            np.column_stack([2 - side, 2 + 0 * side]),
            np.column_stack([0 * side, 2 - side]),
        ]
    )
    xy = np.concatenate([sq, sq[:30]]) + np.random.default_rng(3).normal(0, 0.01, (110, 2))
    gt = Trajectory(np.arange(110) * 0.1, np.column_stack([xy, np.zeros(110)]))
    rel = relations_L(gt, LParams(radius=0.2, away=0.5))
    expect = brute_force_L(xy, 0.2, 0.5)
    i, j = np.round(rel.t1 * 10).astype(int), np.round(rel.t2 * 10).astype(int)
    got = list(zip(i.tolist(), j.tolist(), strict=True))
    assert got == expect
    assert len(got) >= 30  # the second lap returns along the first 3 m
    check_deltas(gt, rel)


def test_L_standing_still_is_not_a_loop():
    gt = Trajectory(np.arange(50) * 0.1, np.zeros((50, 3)))
    assert len(relations_L(gt)) == 0


def est_with_early_rotation_error(gt: Trajectory, k: int, err: float) -> Trajectory:
    """The estimate makes one rotation error `err` at sample k and is perfect otherwise."""
    d = relative(gt.poses[:-1], gt.poses[1:])
    d[k - 1, 2] += err
    poses = [gt.poses[0]]
    from worker.evaluate.se2 import compose

    for step in d:
        poses.append(compose(poses[-1], step))
    return Trajectory(gt.t, np.array(poses))


def test_B_sample_size_follows_the_thesis_formula(rng):
    gt = wander(rng, 2000)
    est = est_with_early_rotation_error(gt, 1000, 0.05)
    p = BParams(z=1.96, margin=0.05)
    n, s, used = b_sample_size(gt, est, np.random.default_rng(1), p)
    assert used == p.pilot
    assert n == math.ceil((1.96 * s / 0.05) ** 2)
    # s estimates the std over all pairs of the run: compare with an independent census
    i, j = np.triu_indices(2000, k=1)
    pick = np.random.default_rng(2).choice(i.size, 200_000, replace=False)
    dg = relative(gt.poses[i[pick]], gt.poses[j[pick]])
    de = relative(est.poses[i[pick]], est.poses[j[pick]])
    census = np.std(np.hypot(*(de - dg)[:, :2].T), ddof=1)
    assert s == pytest.approx(census, rel=0.15)


def test_B_is_deterministic_for_a_seed_and_draws_ground_truth_pairs(rng):
    gt = wander(rng, 1500)
    est = est_with_early_rotation_error(gt, 300, 0.05)
    a = relations_B(gt, est, np.random.default_rng(7))
    b = relations_B(gt, est, np.random.default_rng(7))
    c = relations_B(gt, est, np.random.default_rng(8))
    assert len(a) > 100
    for x, y in ((a.t1, b.t1), (a.t2, b.t2), (a.delta, b.delta)):
        assert x.tobytes() == y.tobytes()
    assert a.t1.tobytes() != c.t1.tobytes()
    assert (a.t1 < a.t2).all()
    check_deltas(gt, a)


def test_B_cap_warns_and_floor_applies(rng):
    gt = wander(rng, 1500)
    est = est_with_early_rotation_error(gt, 300, 0.05)
    with pytest.warns(RelationsCapWarning, match="capped at max_relations = 50"):
        rel = relations_B(gt, est, np.random.default_rng(7), BParams(max_relations=50))
    assert len(rel) == 50
    # a perfect estimate has s = 0: the thesis rule alone gives N = 0, the floor raises it
    thesis = BParams(min_relations=0)
    assert len(relations_B(gt, gt, np.random.default_rng(7), thesis)) == 0
    assert len(relations_B(gt, gt, np.random.default_rng(7), BParams(min_relations=30))) == 30
    # the default floor (issue 17): 500, as many as the pilot
    assert BParams().min_relations == 500
    assert len(relations_B(gt, gt, np.random.default_rng(7))) == 500


def test_B_needs_an_estimate_that_covers_the_ground_truth(rng):
    gt = wander(rng, 300)
    late = Trajectory(gt.t + 1000.0, gt.poses)
    with pytest.raises(InputError, match="0 of 500 pilot relations"):
        relations_B(gt, late, np.random.default_rng(0))


@pytest.mark.parametrize(
    "fn, params",
    [
        (relations_A, AParams(dt=0.0)),
        (relations_M, MParams(distance=-1.0)),
        (relations_L, LParams(radius=float("nan"))),
    ],
)
def test_bad_parameters_are_input_errors(fn, params):
    with pytest.raises(InputError, match="must be a positive number"):
        fn(line(), params)


def test_generate_relations_dispatches_and_checks(rng):
    gt = wander(rng, 600)
    a = generate_relations("A", gt)
    assert a.t1.tobytes() == relations_A(gt).t1.tobytes()
    sm = generate_relations("SM", gt, SMParams(min_distance=1.0))
    assert len(sm) == len(relations_SM(gt, SMParams(min_distance=1.0)))
    with pytest.raises(InputError, match="need the estimate"):
        generate_relations("B", gt)
    with pytest.raises(InputError, match="unknown relation kind"):
        generate_relations("Q", gt)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="take LParams"):
        generate_relations("L", gt, AParams())
    with pytest.raises(InputError, match="max_relations must be >= 0"):
        relations_B(gt, gt, np.random.default_rng(0), BParams(max_relations=-1))
