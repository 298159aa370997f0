"""One delivery of a run, in this process, with the real pipeline on real PostgreSQL: a run
done once, a second delivery doing nothing, the soft time limit failing the run by
compare-and-set with its folder removed, and an exception on a cancelled run leaving it
cancelled. The soft limit arrives as Celery's does: an exception raised from a signal."""

from __future__ import annotations

import os
import signal
import threading
import time
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest
from celery.exceptions import SoftTimeLimitExceeded
from sqlalchemy import func, select

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import Run, RunTrajectory
from backend.db.session import session_scope
from backend.services.execute import Placement, execute_run, signalled
from backend.store import create_job, local_user, save_world
from backend.store.lifecycle import cancel_run, history, history_faults
from tests.backend.plans import rooms_occupancy
from tests.services import scratch_database
from worker.run_params import RunParams
from worker.world.world import World


@pytest.fixture(scope="module")
def pg_url() -> Iterator[str]:
    with scratch_database("mapqual_exec") as url:
        upgrade(url)
        yield url


def _rooms(nx: int, ny: int, room_px: int = 120) -> World:
    """nx x ny rooms of 6 m with 1 m doors."""
    occ = rooms_occupancy(nx, ny, room_px)
    return World.from_array(occ, 0.05, name=f"rooms_{nx}x{ny}")


def _run(url: str, slam: str, time_limit: float, world: World) -> int:
    params = RunParams.from_json({"algorithm": slam, "explore": {"time_limit": time_limit}})
    with session_scope(url) as s:
        owner = local_user(s).id
        sha = world.fingerprint()
        row = save_world(s, owner_id=owner, world=world, sha256=sha, source_format="image")
        job = create_job(
            s, owner_id=owner, world_id=row.id, slam=slam, params=params.to_json(), seeds=[1]
        )
        return job.runs[0].id


def _settings(url: str, runs: Path) -> Settings:
    return Settings(DATABASE_URL=url, MAPQUAL_RUNS_DIR=str(runs), MAPQUAL_RUN_LEASE=30.0)


def _raise_once_running(url: str, run_id: int, exc: BaseException, before=None) -> None:
    """Raise `exc` in the main thread, from a signal handler, once the run has stored its first
    progress (a wall-clock timer could land inside numba's compiler, which swallows it)."""

    def handler(_sig, _frame):
        if before is not None:
            before()
        raise exc

    def watch() -> None:
        for _ in range(1200):
            with session_scope(url) as s:
                if s.get_one(Run, run_id).progress.get("t", 0) > 0:
                    break
            time.sleep(0.1)
        os.kill(os.getpid(), signal.SIGALRM)

    signal.signal(signal.SIGALRM, handler)
    threading.Thread(target=watch, daemon=True).start()


@pytest.fixture(autouse=True)
def _no_alarm() -> Iterator[None]:
    yield
    signal.signal(signal.SIGALRM, signal.SIG_DFL)


def _folders(runs: Path) -> list[str]:
    return sorted(p.name for p in runs.iterdir()) if runs.exists() else []


def test_a_run_is_done_once_and_a_second_delivery_does_nothing(pg_url, tmp_path):
    run_id = _run(pg_url, "oracle", 60.0, _rooms(2, 1))
    settings = _settings(pg_url, tmp_path / "runs")
    first = execute_run(run_id, settings)
    assert first.kind == "done", first
    assert _folders(tmp_path / "runs") == [str(run_id)]  # renamed into place, nothing beside
    folder = tmp_path / "runs" / str(run_id)
    assert (folder / "summary.json").exists()
    with zipfile.ZipFile(folder / "report.zip") as zf:  # made before the rename, with the rest
        on_disk = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}
        assert sorted(zf.namelist()) == sorted(f"run{run_id}/{n}" for n in on_disk - {"report.zip"})
        assert {"summary.json", "sim.log", "relations_B.txt"} <= on_disk
        assert zf.read(f"run{run_id}/sim.log") == (folder / "sim.log").read_bytes()
    again = execute_run(run_id, settings)
    assert (again.kind, again.message) == ("skipped", f"run {run_id}: not run (done)")
    with session_scope(pg_url) as s:
        run = s.get_one(Run, run_id)
        assert (run.status, run.attempts, run.report_dir) == (
            "done", 1, str((tmp_path / "runs" / str(run_id)).resolve())
        )  # fmt: skip
        assert [e.to_status for e in history(s, run_id)] == ["running", "done"]
        n = s.scalar(select(func.count()).where(RunTrajectory.run_id == run_id))
        assert n == 2


def test_the_soft_time_limit_fails_the_run_and_removes_its_folder(pg_url, tmp_path):
    run_id = _run(pg_url, "rbpf", 3000.0, _rooms(5, 3))  # minutes: the limit comes first
    _raise_once_running(pg_url, run_id, SoftTimeLimitExceeded())
    outcome = execute_run(run_id, _settings(pg_url, tmp_path / "runs"))
    assert outcome.kind == "failed", outcome
    assert _folders(tmp_path / "runs") == []  # neither the attempt's folder nor the run's
    with session_scope(pg_url) as s:
        run = s.get_one(Run, run_id)
        assert run.status == "failed" and run.error.startswith("SoftTimeLimitExceeded")
        events = history(s, run_id)
        assert [e.to_status for e in events] == ["running", "failed"]
        assert history_faults(events) == [] and events[1].attempt == run.attempt


def test_a_soft_time_limit_raised_inside_numba_is_reported_as_itself():
    # what CPython made of Celery's soft limit when its signal landed while numba's
    # dispatcher unpickled a cached function (seen in this file's test above, under load):
    # SystemError from the dispatcher, caused by SystemError from _numba_unpickle, caused
    # by the handler's SoftTimeLimitExceeded
    limit = SoftTimeLimitExceeded()
    inner = SystemError("<function _numba_unpickle> returned a result with an exception set")
    inner.__cause__ = limit
    outer = SystemError("CPUDispatcher(<function scan_match_all>) returned a result with an ...")
    outer.__cause__ = inner
    assert signalled(outer) is limit
    assert signalled(limit) is limit
    plain = SystemError("a SystemError of its own")
    assert signalled(plain) is plain
    chained = ValueError("bad")  # other chains are the run's own error, as raised
    chained.__cause__ = KeyError("k")
    assert signalled(chained) is chained
    interrupt = KeyboardInterrupt()
    wrapped = SystemError("... returned a result with an exception set")
    wrapped.__context__ = interrupt
    assert signalled(wrapped) is interrupt


def test_an_exception_on_a_cancelled_run_leaves_it_cancelled(pg_url, tmp_path):
    run_id = _run(pg_url, "rbpf", 3000.0, _rooms(5, 3))

    def cancel() -> None:  # the user cancels; the run breaks before it notices
        with session_scope(pg_url) as s:
            assert cancel_run(s, run_id)

    _raise_once_running(pg_url, run_id, RuntimeError("boom"), before=cancel)
    outcome = execute_run(run_id, _settings(pg_url, tmp_path / "runs"))
    assert outcome.kind == "lost", outcome
    assert _folders(tmp_path / "runs") == []
    with session_scope(pg_url) as s:
        run = s.get_one(Run, run_id)
        assert (run.status, run.error) == ("cancelled", None)
        assert [e.to_status for e in history(s, run_id)] == ["running", "cancelled"]


def test_a_callers_own_folder_gets_the_same_files_as_a_workers_run(pg_url, tmp_path):
    """The placement of `mapqual run -o` and of a batch's runs: the report written straight
    into the folder (no attempt folder, no zip, no sim.log unless named), progress to the
    caller only, the world passed in; the files are the worker's, byte for byte."""
    world = _rooms(2, 1)
    worker_run, own_run = (
        _run(pg_url, "odometry", 60.0, world),
        _run(pg_url, "odometry", 60.0, world),
    )
    settings = _settings(pg_url, tmp_path / "runs")
    assert execute_run(worker_run, settings).kind == "done"
    seen: list[float] = []
    own = tmp_path / "mine"
    place = Placement(report_dir=own, own_folder=True, sim_log=None, lease_s=0.0)
    outcome = execute_run(
        own_run, settings, place=place, on_progress=lambda p: seen.append(p.t), world=world
    )
    assert (outcome.kind, outcome.report_dir) == ("done", str(own.resolve()))
    assert seen and seen == sorted(seen)
    assert _folders(tmp_path) == ["mine", "runs"] and _folders(tmp_path / "runs") == [
        str(worker_run)
    ]
    worker_files = {p.name for p in (tmp_path / "runs" / str(worker_run)).iterdir()}
    assert {p.name for p in own.iterdir()} == worker_files - {"report.zip", "sim.log"}
    for name in ("relations_B.txt", "T.errors", "gt.log", "est.tum", "map.pgm", "map.yaml"):
        assert (own / name).read_bytes() == (
            tmp_path / "runs" / str(worker_run) / name
        ).read_bytes(), name
    with session_scope(pg_url) as s:
        run = s.get_one(Run, own_run)
        assert (run.status, run.report_dir, run.progress) == ("done", str(own.resolve()), {})
        assert run.summary["relations"] == outcome.summary.to_dict()["relations"]


def _interrupt(_progress) -> None:
    raise KeyboardInterrupt


def test_an_interrupt_fails_a_foreground_run_and_leaves_a_workers_to_its_lease(pg_url, tmp_path):
    settings = _settings(pg_url, tmp_path / "runs")
    mine, workers = (
        _run(pg_url, "odometry", 60.0, _rooms(2, 1)),
        _run(pg_url, "odometry", 60.0, _rooms(2, 1)),
    )
    own = tmp_path / "mine"
    place = Placement(report_dir=own, own_folder=True, fail_on_interrupt=True)  # mapqual run -o
    with pytest.raises(KeyboardInterrupt):
        execute_run(mine, settings, place=place, on_progress=_interrupt)
    with pytest.raises(KeyboardInterrupt):
        execute_run(workers, settings, on_progress=_interrupt)
    with session_scope(pg_url) as s:
        run = s.get_one(Run, mine)
        assert (run.status, run.error) == ("failed", "KeyboardInterrupt: ")
        assert [e.to_status for e in history(s, mine)] == ["running", "failed"]
        assert s.get_one(Run, workers).status == "running"  # another delivery takes it over
    assert own.is_dir()  # the user's folder is the user's
