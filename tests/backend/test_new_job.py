"""create_job, the one way a job is written: the rows its Core statements store (checked by
hand against what the ORM's defaults give a run), and its answer is what reading them back
gives, on SQLite and PostgreSQL."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import func, select

from backend.core.schemas import JobOut
from backend.db.models import Job, Run
from backend.db.session import session_scope
from backend.store import add_user, get_or_create_world
from backend.store.jobs import NewJob, create_job
from worker.run_params import RunParams


def _world(s) -> tuple[int, int]:
    user, _ = add_user(s, "alice")
    occ = np.zeros((10, 12), bool)
    occ[0, :] = True
    w = get_or_create_world(
        s, owner_id=user.id, name="w", sha256="a" * 64, source_format="image", source_path=None,
        resolution=0.05, origin=(0, 0), occ=occ, start_pose=(0.2, 0.2, 0), facts={},
    )  # fmt: skip
    return user.id, w.id


# the run columns a new run gets besides its ids (what the ORM's defaults give it)
COLUMNS = ("seed", "slam", "params", "status", "progress", "metrics", "summary", "attempts",
           "attempt", "broker_epoch", "time_limit_s", "outcome", "started_at")  # fmt: skip


def _runs(s, job_id: int) -> list[tuple]:
    rows = s.scalars(select(Run).where(Run.job_id == job_id).order_by(Run.id))
    return [tuple(getattr(r, c) for c in COLUMNS) for r in rows]


def test_a_job_inserted_by_core_reads_back_as_stored(db_url):
    params = {"explore": {"time_limit": 90.0}, "slam": {"particles": 7}}
    kw = dict(slam="odometry", params=params, seeds=[5, 2, 9], broker_epoch="e" * 32)
    with session_scope(db_url) as s:
        owner, world = _world(s)
        new = create_job(s, owner_id=owner, world_id=world, idempotency_key="k", **kw)
        again = create_job(s, owner_id=owner, world_id=world, idempotency_key="k", **kw)
    with session_scope(db_url) as s:
        assert isinstance(new, NewJob) and len(new.runs) == 3
        assert again == new  # the same key: the first job, read back from the database
        assert s.scalar(select(func.count(Job.id))) == 1
        # by hand: seeds in the order asked, queued, the time limit copied from the params
        expected = (5, "odometry", params, "queued", {}, {}, {}, 0, None, "e" * 32, 90.0, None,
                    None)  # fmt: skip
        assert _runs(s, new.id)[0] == expected
        assert [r[0] for r in _runs(s, new.id)] == [5, 2, 9]
        job = s.get_one(Job, new.id)
        assert (job.owner_id, job.world_id, job.status, job.idempotency_key) == (
            owner, world, "queued", "k",
        )  # fmt: skip
        # the answer built from what was inserted is the answer read from the database
        assert JobOut.of(new) == JobOut.of(job)
        assert [r.id for r in new.runs] == [r.id for r in job.runs]


def test_runs_without_a_time_limit_store_none(db_url):
    # None: the quota counts the pipeline's default for them (tests/backend/api/test_quotas.py)
    with session_scope(db_url) as s:
        owner, world = _world(s)
        new = create_job(s, owner_id=owner, world_id=world, slam="rbpf", params={}, seeds=[1])
    with session_scope(db_url) as s:
        assert s.get_one(Run, new.runs[0].id).time_limit_s is None


def test_a_job_needs_a_seed(db_url):
    with session_scope(db_url) as s:
        owner, world = _world(s)
        with pytest.raises(ValueError, match="at least one seed"):
            create_job(s, owner_id=owner, world_id=world, slam="rbpf", params={}, seeds=[])


def test_typed_parameters_are_stored_as_their_json_and_each_variant_on_every_seed(db_url):
    fast = RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 60.0}})
    slow = RunParams.from_json({"algorithm": "rbpf", "explore": {"time_limit": 120.0}})
    with session_scope(db_url) as s:
        owner, world = _world(s)
        new = create_job(s, owner_id=owner, world_id=world, slam="odometry+rbpf", seeds=[1, 2],
                         variants=[("odometry", fast), ("rbpf", slow)])  # fmt: skip
    with session_scope(db_url) as s:
        runs = s.scalars(select(Run).where(Run.job_id == new.id).order_by(Run.id)).all()
        assert [(r.slam, r.seed, r.time_limit_s) for r in runs] == [
            ("odometry", 1, 60.0), ("odometry", 2, 60.0), ("rbpf", 1, 120.0), ("rbpf", 2, 120.0)
        ]  # fmt: skip
        assert RunParams.from_json(runs[2].params) == slow
        assert s.get_one(Job, new.id).params == fast.to_json()  # the job keeps the first's
