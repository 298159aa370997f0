"""insert_job: the rows its Core statements store are those of a job made through the ORM, and
its answer is what reading them back gives, on SQLite and PostgreSQL."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import select

from backend.db.models import Job, Run
from backend.db.session import session_scope
from backend.new_job import NewJob, insert_job
from backend.schemas import JobOut
from backend.store import add_user, create_job, get_or_create_world


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


def test_a_job_inserted_by_core_reads_back_as_one_made_by_the_orm(db_url):
    params = {"explore": {"time_limit": 90.0}, "slam": {"particles": 7}}
    kw = dict(slam="odometry", params=params, seeds=[5, 2, 9], broker_epoch="e" * 32)
    with session_scope(db_url) as s:
        owner, world = _world(s)
        new = insert_job(s, owner_id=owner, world_id=world, idempotency_key="k", **kw)
        orm = create_job(s, owner_id=owner, world_id=world, **kw)
    with session_scope(db_url) as s:
        assert isinstance(new, NewJob) and len(new.runs) == 3
        assert _runs(s, new.id) == _runs(s, orm.id)
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
        new = insert_job(s, owner_id=owner, world_id=world, slam="rbpf", params={}, seeds=[1])
    with session_scope(db_url) as s:
        assert s.get_one(Run, new.runs[0].id).time_limit_s is None


def test_a_job_needs_a_seed(db_url):
    with session_scope(db_url) as s:
        owner, world = _world(s)
        with pytest.raises(ValueError, match="at least one seed"):
            insert_job(s, owner_id=owner, world_id=world, slam="rbpf", params={}, seeds=[])
