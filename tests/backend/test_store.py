"""The store against real SQLite and PostgreSQL: round trips, re-runs, job status, replacement."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import func, select

from backend.db.models import Job, Run, RunTrajectory, User
from backend.db.session import session_scope
from backend.store import (
    add_user,
    create_job,
    get_or_create_world,
    list_runs,
    load_map,
    load_trajectory,
    local_user,
    mark_run_failed,
    mark_run_started,
    store_run_result,
    user_for_key,
    world_occupancy,
)
from backend.store.lifecycle import TransitionRefused
from tests.summaries import make_summary, relation, stats


def _world(session, sha="a" * 64):
    occ = np.zeros((30, 40), dtype=bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    occ[10, 5] = True  # asymmetric, so a flipped or transposed grid would not compare equal
    return get_or_create_world(
        session,
        owner_id=local_user(session).id,
        name="box",
        sha256=sha,
        source_format="image",
        source_path=None,
        resolution=0.05,
        origin=(1.5, -2.0),
        occ=occ,
        start_pose=(1.0, 0.75, 0.0),
        facts={"free_area_m2": 2.5},
    ), occ


def _summary(b_t=0.12, b_r=0.004):
    return make_summary(
        outcome="completed",
        reason=None,
        stop="no_frontier",
        coverage=0.97,
        relations={"B": relation(stats(b_t), stats(b_r))},
        timings={"sim_time_s": 600.0, "wall_time_s": 12.5},
    )


def _result_arrays(n=1000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    gt = np.cumsum(rng.normal(size=(n, 3)), axis=0)
    est = gt + rng.normal(scale=0.01, size=(n, 3))
    grid = rng.integers(-1, 101, size=(50, 60)).astype(np.int8)
    return t, gt, est, grid


def test_world_is_stored_once_per_content_and_occupancy_round_trips(db_url):
    with session_scope(db_url) as s:
        w1, occ = _world(s)
        w2, _ = _world(s)
        assert w1.id == w2.id
        assert np.array_equal(world_occupancy(w1), occ)
        assert (w1.origin_x, w1.origin_y, w1.width_px, w1.height_px) == (1.5, -2.0, 40, 30)


def test_result_round_trips_bit_for_bit_and_fills_headline_columns(db_url):
    t, gt, est, grid = _result_arrays()
    with session_scope(db_url) as s:
        world, _ = _world(s)
        job = create_job(
            s,
            owner_id=world.owner_id,
            world_id=world.id,
            slam="rbpf",
            params={"seed": 1},
            seeds=[1],
        )
        run_id = job.runs[0].id
        mark_run_started(s, run_id)
        store_run_result(
            s,
            run_id,
            summary=_summary(),
            t=t,
            pose_gt=gt,
            pose_est=est,
            map_ros=grid,
            map_resolution=0.05,
            map_origin=(-3.0, 4.0),
            report_dir="runs/1",
        )
    with session_scope(db_url) as s:
        t2, gt2 = load_trajectory(s, run_id, "gt")
        _, est2 = load_trajectory(s, run_id, "est")
        grid2, res, origin = load_map(s, run_id)
        run = s.get_one(Run, run_id)
        assert np.array_equal(t2, t) and np.array_equal(gt2, gt) and np.array_equal(est2, est)
        assert np.array_equal(grid2, grid) and grid2.dtype == np.int8
        assert (res, origin) == (0.05, (-3.0, 4.0))
        assert (run.status, run.outcome, run.coverage) == ("done", "completed", 0.97)
        assert (run.b_mean_t, run.b_mean_r, run.sim_time) == (0.12, 0.004, 600.0)
        assert run.job.status == "done"
        # one row per trajectory, not per pose
        assert s.scalar(select(func.count()).select_from(RunTrajectory)) == 2


def test_a_run_taken_over_keeps_only_the_new_holders_result(db_url):
    t, gt, est, grid = _result_arrays()
    with session_scope(db_url) as s:
        world, _ = _world(s)
        run_id = (
            create_job(
                s, owner_id=world.owner_id, world_id=world.id, slam="rbpf", params={}, seeds=[3]
            )
            .runs[0]
            .id
        )
    # attempt "a" claims; "b" takes over once a's heartbeat is older than the lease (0 s)
    for attempt in ("a" * 32, "b" * 32):
        with session_scope(db_url) as s:
            mark_run_started(s, run_id, attempt, lease_s=0.0)
    for attempt, b_t in (("b" * 32, 0.25), ("a" * 32, 0.5)):
        try:
            with session_scope(db_url) as s:
                store_run_result(
                    s,
                    run_id,
                    summary=_summary(b_t=b_t),
                    t=t[: 500 + int(b_t * 4)],
                    pose_gt=gt[: 500 + int(b_t * 4)],
                    pose_est=est[: 500 + int(b_t * 4)],
                    map_ros=grid,
                    map_resolution=0.05,
                    map_origin=(0, 0),
                    report_dir=None,
                    attempt=attempt,
                )
        except TransitionRefused:
            assert attempt == "a" * 32  # the superseded attempt stores nothing
    with session_scope(db_url) as s:
        assert s.scalar(select(func.count()).select_from(RunTrajectory)) == 2
        run = s.get_one(Run, run_id)
        assert (run.b_mean_t, run.attempt, run.attempts) == (0.25, "b" * 32, 2)
        assert len(load_trajectory(s, run_id, "est")[0]) == 501


def test_same_world_params_and_seed_again_make_a_new_run(db_url):
    with session_scope(db_url) as s:
        world, _ = _world(s)
        a = (
            create_job(
                s,
                owner_id=world.owner_id,
                world_id=world.id,
                slam="rbpf",
                params={"x": 1},
                seeds=[7],
            )
            .runs[0]
            .id
        )
        b = (
            create_job(
                s,
                owner_id=world.owner_id,
                world_id=world.id,
                slam="rbpf",
                params={"x": 1},
                seeds=[7],
            )
            .runs[0]
            .id
        )
        assert a != b
        assert [r.id for r in list_runs(s)] == [b, a]


def test_job_status_follows_its_runs(db_url):
    t, gt, est, grid = _result_arrays(n=20)
    with session_scope(db_url) as s:
        world, _ = _world(s)
        job = create_job(
            s, owner_id=world.owner_id, world_id=world.id, slam="odometry", params={}, seeds=[1, 2]
        )
        job_id, (r1, r2) = job.id, [r.id for r in job.runs]
        assert job.status == "queued"
        mark_run_started(s, r1)
        assert s.get_one(Job, job_id).status == "running"
        store_run_result(
            s,
            r1,
            summary=_summary(),
            t=t,
            pose_gt=gt,
            pose_est=est,
            map_ros=grid,
            map_resolution=0.05,
            map_origin=(0, 0),
            report_dir=None,
        )
        assert s.get_one(Job, job_id).status == "running"  # r2 still queued
        attempt = mark_run_started(s, r2).attempt
        assert not mark_run_failed(s, r2, "worker crashed", "another attempt")
        assert mark_run_failed(s, r2, "worker crashed", attempt)
        assert s.get_one(Job, job_id).status == "failed"


def test_a_failed_transaction_leaves_earlier_data_intact(db_url):
    with session_scope(db_url) as s:
        world, _ = _world(s)
        run_id = (
            create_job(
                s, owner_id=world.owner_id, world_id=world.id, slam="rbpf", params={}, seeds=[1]
            )
            .runs[0]
            .id
        )
    t, gt, est, grid = _result_arrays(n=10)
    with pytest.raises(RuntimeError), session_scope(db_url) as s:
        mark_run_started(s, run_id)
        store_run_result(
            s,
            run_id,
            summary=_summary(),
            t=t,
            pose_gt=gt,
            pose_est=est,
            map_ros=grid,
            map_resolution=0.05,
            map_origin=(0, 0),
            report_dir=None,
        )
        raise RuntimeError("crash before commit")
    with session_scope(db_url) as s:
        run = s.get_one(Run, run_id)
        assert run.status == "queued" and run.outcome is None
        assert s.scalar(select(func.count()).select_from(RunTrajectory)) == 0


def test_unknown_trajectory_kind_is_rejected(db_url):
    with session_scope(db_url) as s, pytest.raises(ValueError, match="gt"):
        load_trajectory(s, 1, "truth")


def test_worlds_are_per_owner_and_keys_are_stored_hashed(db_url):
    with session_scope(db_url) as s:
        alice, key = add_user(s, "alice")
        assert key not in alice.key_hash and user_for_key(s, key).id == alice.id
        assert user_for_key(s, key + "x") is None
        mine, _ = _world(s)
        occ = np.zeros((5, 5), bool)
        hers = get_or_create_world(
            s,
            owner_id=alice.id,
            name="box",
            sha256="a" * 64,
            source_format="image",
            source_path=None,
            resolution=0.05,
            origin=(0, 0),
            occ=occ,
            start_pose=(0, 0, 0),
            facts={},
        )
        assert hers.id != mine.id  # same content, other owner: a world of her own
        with pytest.raises(ValueError, match="exists already"):
            add_user(s, "alice")


def test_idempotency_key_returns_the_first_job(db_url):
    with session_scope(db_url) as s:
        world, _ = _world(s)
        kw = dict(owner_id=world.owner_id, world_id=world.id, slam="rbpf", params={}, seeds=[1])
        a = create_job(s, **kw, idempotency_key="k1")
        b = create_job(s, **kw, idempotency_key="k1")
        c = create_job(s, **kw, idempotency_key="k2")
        assert a.id == b.id != c.id
        assert len(a.runs) == 1


def test_the_local_user_made_by_two_processes_at_once_is_one_user(db_url, monkeypatch):
    # two `mapqual batch` started together on a new database: both find no local user, one
    # stores it first; the other's insert then breaks the unique name and must return the
    # first one's user (it raised IntegrityError out of the CLI before)
    import backend.store.users as users

    real_new = users._new_user
    winner = []

    def stored_after_the_other_process(session, name, is_admin):
        with session_scope(db_url) as other:  # the other process, committing first
            winner.append(real_new(other, name, is_admin)[0].id)
        return real_new(session, name, is_admin)

    monkeypatch.setattr(users, "_new_user", stored_after_the_other_process)
    with session_scope(db_url) as s:
        got = local_user(s).id
        assert s.get(User, got).name == "local"  # the session is usable after the failure
    assert winner and got == winner[0]
    with session_scope(db_url) as s:
        assert s.scalar(select(func.count()).select_from(User)) == 1
