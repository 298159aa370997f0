"""Run status changes against real SQLite and PostgreSQL: each one a compare-and-set with its
history line; illegal changes refused; a cancel racing a claim; a failure after a cancel; two
attempts' results, of which only the holder's is kept, with its folder."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest
from sqlalchemy import func, select

from backend.db.models import Run, RunEvent, RunTrajectory
from backend.db.session import session_scope
from backend.services.progress import ProgressReporter
from backend.store import (
    create_job,
    get_or_create_world,
    local_user,
    mark_run_failed,
    store_run_result,
)
from backend.store.lifecycle import (
    TransitionRefused,
    attempt_dir,
    cancel_run,
    claim_run,
    history,
    history_faults,
    new_attempt,
    requeue,
)
from tests.summaries import make_summary
from worker.pipeline import RunCancelled, RunProgress, RunSuperseded

STATUSES = ("queued", "running", "done", "failed", "cancelled")
LEASE_S = 3600.0  # a live holder is never taken over in these tests unless said so


def _job(s, n_runs=1) -> list[int]:
    occ = np.zeros((20, 20), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    world = get_or_create_world(
        s, owner_id=local_user(s).id, name="box", sha256="b" * 64, source_format="image",
        source_path=None, resolution=0.05, origin=(0, 0), occ=occ, start_pose=(0.5, 0.5, 0),
        facts={},
    )  # fmt: skip
    job = create_job(
        s, owner_id=world.owner_id, world_id=world.id, slam="odometry", params={},
        seeds=list(range(n_runs)),
    )  # fmt: skip
    return [r.id for r in job.runs]


def _result(s, run_id: int, attempt: str | None, folder: Path | None = None, final=None):
    t = np.arange(5) * 0.1
    poses = np.zeros((5, 3))
    return store_run_result(
        s, run_id, summary=make_summary(), t=t, pose_gt=poses, pose_est=poses,
        map_ros=np.zeros((4, 4), np.int8), map_resolution=0.05, map_origin=(0, 0),
        report_dir=None if final is None else str(final), attempt=attempt, folder=folder,
    )  # fmt: skip


def _in_status(url: str, status: str) -> tuple[int, str | None]:
    """A run brought to `status` by legal changes, and its holder's attempt (if any)."""
    with session_scope(url) as s:
        (run_id,) = _job(s)
    attempt = new_attempt()
    with session_scope(url) as s:
        if status == "queued":
            return run_id, None
        assert claim_run(s, run_id, attempt, LEASE_S)[0] == "claimed"
        if status == "done":
            _result(s, run_id, attempt)
        elif status == "failed":
            assert mark_run_failed(s, run_id, "boom", attempt)
        elif status == "cancelled":
            assert cancel_run(s, run_id)
    return run_id, attempt


def _status(url: str, run_id: int) -> tuple[str, int]:
    with session_scope(url) as s:
        n = s.scalar(select(func.count()).select_from(RunEvent).where(RunEvent.run_id == run_id))
        return s.get_one(Run, run_id).status, n


def _try(url: str, op: str, run_id: int, holder: str | None) -> bool:
    """One change of each kind, by the run's holder where one is needed; True if it was made."""
    with session_scope(url) as s:
        if op == "claim":
            return claim_run(s, run_id, new_attempt(), LEASE_S)[0] == "claimed"
        if op == "take over":
            return claim_run(s, run_id, new_attempt(), 0.0)[0] == "claimed"
        if op == "finish":
            try:
                _result(s, run_id, holder or new_attempt())
                return True
            except TransitionRefused:
                return False
        if op == "fail":
            return mark_run_failed(s, run_id, "boom", holder or new_attempt())
        if op == "cancel":
            return cancel_run(s, run_id)
        return requeue(s, run_id, "test")


# what each change does from each status: the legal transitions, and nothing else
EXPECTED = {
    "claim": {"queued": "running"},
    "take over": {"queued": "running", "running": "running"},
    "finish": {"running": "done"},
    "fail": {"running": "failed"},
    "cancel": {"queued": "cancelled", "running": "cancelled"},
    "requeue": {"running": "queued", "failed": "queued"},
}


@pytest.mark.parametrize("op", list(EXPECTED))
def test_every_change_is_made_only_from_where_it_is_legal(db_url, op):
    for status in STATUSES:
        run_id, holder = _in_status(db_url, status)
        before, n_events = _status(db_url, run_id)
        assert before == status
        made = _try(db_url, op, run_id, holder)
        after, n_after = _status(db_url, run_id)
        assert made == (status in EXPECTED[op]), (op, status)
        assert after == EXPECTED[op].get(status, status), (op, status)
        assert n_after == n_events + made  # one history line per change, none when refused
        with session_scope(db_url) as s:
            assert history_faults(history(s, run_id)) == []


def test_a_stranger_attempt_can_neither_finish_nor_fail_a_run(db_url):
    run_id, holder = _in_status(db_url, "running")
    stranger = new_attempt()
    with pytest.raises(TransitionRefused), session_scope(db_url) as s:
        _result(s, run_id, stranger)
    with session_scope(db_url) as s:
        assert not mark_run_failed(s, run_id, "boom", stranger)
        assert claim_run(s, run_id, stranger, LEASE_S)[0] == "busy"  # the holder is alive
    assert _status(db_url, run_id)[0] == "running"
    with session_scope(db_url) as s:
        assert s.get_one(Run, run_id).attempt == holder
        assert s.scalar(select(func.count()).select_from(RunTrajectory)) == 0


def test_a_failure_after_a_cancel_keeps_the_run_cancelled(db_url):
    run_id, holder = _in_status(db_url, "running")
    with session_scope(db_url) as s:
        assert cancel_run(s, run_id)
    with session_scope(db_url) as s:
        assert not mark_run_failed(s, run_id, "RuntimeError: boom", holder)
    with pytest.raises(TransitionRefused), session_scope(db_url) as s:
        _result(s, run_id, holder)
    with session_scope(db_url) as s:
        run = s.get_one(Run, run_id)
        assert (run.status, run.error, run.finished_at is not None) == ("cancelled", None, True)
        assert [e.to_status for e in history(s, run_id)] == ["running", "cancelled"]


def test_a_cancel_racing_a_claim_always_ends_cancelled(db_url):
    with session_scope(db_url) as s:
        run_ids = _job(s, n_runs=12)
    answers: dict[int, str] = {}

    def claim(run_id: int, barrier: threading.Barrier) -> None:
        barrier.wait()
        with session_scope(db_url) as s:
            answers[run_id] = claim_run(s, run_id, new_attempt(), LEASE_S)[0]

    def cancel(run_id: int, barrier: threading.Barrier) -> None:
        barrier.wait()
        with session_scope(db_url) as s:
            assert cancel_run(s, run_id)  # queued or running: it is always cancellable

    for run_id in run_ids:
        barrier = threading.Barrier(2)
        threads = [threading.Thread(target=f, args=(run_id, barrier)) for f in (claim, cancel)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
    with session_scope(db_url) as s:
        for run_id in run_ids:
            run = s.get_one(Run, run_id)
            events = history(s, run_id)
            assert run.status == "cancelled" and history_faults(events) == []
            if answers[run_id] == "claimed":  # the claim won: it was then cancelled running
                assert [e.to_status for e in events] == ["running", "cancelled"]
            else:  # the cancel won: the claim found it cancelled and did nothing
                assert answers[run_id] == "cancelled"
                assert [e.to_status for e in events] == ["cancelled"]


def _progress(t: float) -> RunProgress:
    pose = np.zeros(3)
    return RunProgress(
        t=t, coverage=0.1, pose_gt=pose, pose_est=pose, status="exploring", goals_reached=0,
        wall_s=t, rtf=1.0,
    )  # fmt: skip


def test_the_heartbeat_stops_an_attempt_that_was_taken_over_or_cancelled(db_url):
    run_id, first = _in_status(db_url, "running")
    beat = ProgressReporter(db_url, run_id, None, attempt=first, store_every_s=0.0)
    beat(_progress(1.0))
    with session_scope(db_url) as s:
        before = s.get_one(Run, run_id).heartbeat_at
    beat(_progress(2.0))
    with session_scope(db_url) as s:
        run = s.get_one(Run, run_id)
        assert run.progress["t"] == 2.0 and run.heartbeat_at > before
    second = new_attempt()
    with session_scope(db_url) as s:
        assert claim_run(s, run_id, second, 0.0)[0] == "claimed"  # the lease ran out
    with pytest.raises(RunSuperseded):
        beat(_progress(3.0))
    with session_scope(db_url) as s:
        assert s.get_one(Run, run_id).progress == {}  # the loser wrote nothing more
        assert cancel_run(s, run_id)
    with pytest.raises(RunCancelled) as err:
        ProgressReporter(db_url, run_id, None, attempt=second, store_every_s=0.0)(_progress(1.0))
    assert not isinstance(err.value, RunSuperseded)


def test_of_two_attempts_only_the_holders_result_and_folder_are_kept(db_url, tmp_path):
    run_id, first = _in_status(db_url, "running")
    final = tmp_path / "runs" / str(run_id)
    final.mkdir(parents=True)
    (final / "stale.txt").write_text("an attempt that crashed between rename and commit")
    second = new_attempt()
    with session_scope(db_url) as s:
        assert claim_run(s, run_id, second, 0.0)[0] == "claimed"
    for attempt in (first, second):
        attempt_dir(final, attempt).mkdir()
        (attempt_dir(final, attempt) / "who.txt").write_text(attempt)
    with pytest.raises(TransitionRefused), session_scope(db_url) as s:
        _result(s, run_id, first, attempt_dir(final, first), final)
    assert (final / "stale.txt").exists()  # the loser touched nothing
    with session_scope(db_url) as s:
        _result(s, run_id, second, attempt_dir(final, second), final)
    assert sorted(p.name for p in final.iterdir()) == ["who.txt"]
    assert (final / "who.txt").read_text() == second
    assert not attempt_dir(final, second).exists()
    with session_scope(db_url) as s:
        run = s.get_one(Run, run_id)
        assert (run.status, run.attempt, run.attempts, run.report_dir) == (
            "done", second, 2, str(final)
        )  # fmt: skip
        assert s.scalar(select(func.count()).select_from(RunTrajectory)) == 2
        events = history(s, run_id)
        assert history_faults(events) == []
        assert [(e.to_status, e.attempt) for e in events] == [
            ("running", first), ("running", second), ("done", second)
        ]  # fmt: skip


def test_history_faults_catch_an_illegal_history():
    def ev(frm, to, attempt="x"):
        return RunEvent(run_id=1, from_status=frm, to_status=to, attempt=attempt)

    assert history_faults([ev("queued", "running"), ev("running", "done")]) == []
    assert history_faults([ev("queued", "running"), ev("running", "done", "y")])
    assert history_faults([ev("queued", "done")])
    assert history_faults([ev("queued", "running"), ev("queued", "running")])
    assert history_faults([ev("queued", "cancelled"), ev("cancelled", "queued")])
