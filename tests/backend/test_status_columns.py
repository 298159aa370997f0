"""Status columns on SQLite and PostgreSQL: the database holds the plain strings it held before
the enums (no migration), rows read back as `StrEnum` members, an unknown value is refused."""

from __future__ import annotations

import numpy as np
import pytest
from sqlalchemy import select, text
from sqlalchemy.exc import StatementError

from backend.db.models import Job, Run, World
from backend.db.session import session_scope
from backend.store import create_job, get_or_create_world, local_user, mark_run_started
from backend.store.lifecycle import LEGAL
from worker.status import JobStatus, RunStatus, WorldStatus


def _job(session) -> Job:
    world = get_or_create_world(
        session, owner_id=local_user(session).id, name="box", sha256="b" * 64,
        source_format="image", source_path=None, resolution=0.05, origin=(0.0, 0.0),
        occ=np.zeros((4, 4), dtype=bool), start_pose=(0.1, 0.1, 0.0), facts={},
    )  # fmt: skip
    return create_job(
        session, owner_id=world.owner_id, world_id=world.id, slam="odometry", params={},
        seeds=[1, 2],
    )  # fmt: skip


def test_statuses_are_stored_as_the_plain_strings_and_read_back_as_members(db_url):
    with session_scope(db_url) as s:
        job = _job(s)
        job_id, (r1, r2) = job.id, [r.id for r in job.runs]
        mark_run_started(s, r1)
    with session_scope(db_url) as s:
        raw = dict(s.execute(text("SELECT id, status FROM runs")).all())
        assert raw == {r1: "running", r2: "queued"}  # what the column held before the enums
        assert s.execute(text("SELECT status FROM jobs")).scalar_one() == "running"
        assert s.execute(text("SELECT status FROM worlds")).scalar_one() == "ready"
        run = s.get_one(Run, r1)
        assert type(run.status) is RunStatus and run.status is RunStatus.RUNNING
        assert type(s.get_one(Job, job_id).status) is JobStatus
        assert type(s.get_one(World, run.world_id).status) is WorldStatus
        (event,) = s.execute(text("SELECT from_status, to_status FROM run_events")).all()
        assert tuple(event) == ("queued", "running")


def test_an_unknown_status_is_refused_before_it_reaches_the_database(db_url):
    with session_scope(db_url) as s:
        run_id = _job(s).runs[0].id
    refused = pytest.raises(StatementError, match="'paused' is not a valid RunStatus")
    with refused, session_scope(db_url) as s:
        s.get_one(Run, run_id).status = "paused"
    with session_scope(db_url) as s:
        assert s.get_one(Run, run_id).status == "queued"


def test_a_stored_string_that_is_no_status_fails_the_read_and_null_reads_as_none(db_url):
    with session_scope(db_url) as s:
        run_id = _job(s).runs[0].id
    with session_scope(db_url) as s:  # written around the ORM, as a stray script might
        s.execute(text("UPDATE runs SET status = 'paused' WHERE id = :id"), {"id": run_id})
    unreadable = pytest.raises(ValueError, match="'paused' is not a valid RunStatus")
    with unreadable, session_scope(db_url) as s:
        s.get_one(Run, run_id)
    with session_scope(db_url) as s:  # the Core read path of GET /jobs/{id} decodes alike
        s.execute(text("UPDATE runs SET status = 'done' WHERE id = :id"), {"id": run_id})
        row = s.execute(select(Run.status, Run.outcome).where(Run.id == run_id)).one()
        assert row.status is RunStatus.DONE and row.outcome is None


def test_every_legal_change_is_between_run_statuses():
    assert {status for change in LEGAL for status in change} == set(RunStatus)
    assert all(isinstance(a, RunStatus) and isinstance(b, RunStatus) for a, b in LEGAL)
