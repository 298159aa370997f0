"""`mapqual batch` as a user runs it: real processes, a real database, a real Celery worker on
real Redis. Tables are checked against the per-run summaries with arithmetic written here;
the local pool and Celery give the same figures; a killed batch resumes with no run lost or
done twice."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from sqlalchemy import create_engine, select, text

from backend.db.models import Job, Run
from backend.db.session import get_engine, session_scope
from tests.services import ensure_postgres, ensure_redis

REDIS_DB = 12  # apart from the API tests (13) and the queue tests (14)
ARGS = ["--seeds", "1-2", "--slam", "odometry", "--laser-noise", "0,0.1", "--time-limit", "30"]
METRICS = ("world", "variant", "noise", "slam", "seed", "outcome", "reason", "good", "coverage",
           "b_mean_t", "b_std_t", "b_max_t", "b_mean_r", "b_n", "a_mean_t", "a_n", "sm_n",
           "ate_rmse_t", "path_length_m", "sim_time_s", "key")  # fmt: skip


def _world(folder: Path, name: str, furniture: bool = False) -> None:
    img = np.full((120, 200), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:, 100] = 0
    img[50:70, 100] = 255
    if furniture:
        img[30:34, 30:34] = img[80:84, 150:154] = img[20:24, 140:144] = 0
    Image.fromarray(img).save(folder / f"{name}.png")
    (folder / f"{name}.yaml").write_text(f"image: {name}.png\nresolution: 0.05\n")


@pytest.fixture(scope="module")
def worlds(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("worlds")
    _world(folder, "rooms")
    _world(folder, "rooms_furnitures", furniture=True)
    return folder


def _mapqual(cwd, env, *args, timeout=600):
    return subprocess.run(
        [sys.executable, "-m", "mapqual", *args], capture_output=True, text=True,
        env={**os.environ, "COLUMNS": "200", **env}, cwd=cwd, timeout=timeout,
    )  # fmt: skip


def _csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def _num(v):
    return None if v in ("", None) else float(v)


def _check_tables(out: Path, summaries: dict[str, dict]) -> None:
    """Every table of OUT against the per-run summaries (keyed by run key)."""
    runs = {r["key"]: r for r in _csv(out / "runs.csv")}
    assert set(runs) == set(summaries)
    for key, s in summaries.items():
        row, b = runs[key], s["relations"]["B"]
        assert (row["outcome"], row["reason"] or None) == (s["outcome"], s["reason"])
        assert float(row["coverage"]) == s["coverage"]
        assert int(row["b_n"]) == b["translation"]["n"]
        if b["translation"]["n"]:
            assert float(row["b_mean_t"]) == b["translation"]["mean"]
            assert float(row["b_max_r"]) == b["rotation"]["max"]
    by_cond: dict[tuple, list] = {}
    for key, s in summaries.items():
        by_cond.setdefault((runs[key]["world"], float(runs[key]["noise"])), []).append(s)
    success = {(r["world"], float(r["noise"])): r for r in _csv(out / "success.csv")}
    assert set(success) == set(by_cond)
    trans = {r["ENVIRONMENT"]: r for r in _csv(out / "translation.csv")}
    rot = {r["ENVIRONMENT"]: r for r in _csv(out / "rotation.csv")}
    for (world, noise), ss in by_cond.items():
        done = [s for s in ss if s["outcome"] == "completed"]
        row = success[(world, noise)]
        assert (int(row["runs"]), int(row["completed"])) == (len(ss), len(done))
        assert int(row["time_limit"]) == sum(s["reason"] == "time_limit" for s in ss)
        ok = [s["relations"]["B"] for s in done if s["relations"]["B"]["translation"]["n"]]
        env = f"{world} noise {noise:g}"
        assert (env in trans) == bool(ok)
        for table, axis in ((trans, "translation"), (rot, "rotation")):
            if not ok:
                continue
            for col, stat in (
                ("MEAN", "mean"),
                ("STD", "std"),
                ("MAX", "max"),
                ("NUMMEASURES", "n"),
            ):
                expect = sum(b[axis][stat] for b in ok) / len(ok)
                assert float(table[env][col]) == pytest.approx(expect, rel=1e-12, abs=1e-15)


@pytest.fixture(scope="module")
def local_batch(worlds, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("local")
    env = {"DATABASE_URL": f"sqlite:///{tmp / 'm.db'}"}
    r = _mapqual(tmp, env, "batch", str(worlds), *ARGS, "--workers", "2", "-o", "out")
    assert r.returncode == 0, r.stderr
    return tmp, env, r


def test_local_batch_tables_agree_with_each_runs_summary(local_batch):
    tmp, env, r = local_batch
    out = tmp / "out"
    records = [json.loads(p.read_text()) for p in out.glob("runs/*/record.json")]
    assert len(records) == 2 * 2 * 2 and all(rec["status"] == "done" for rec in records)
    summaries = {
        rec["key"]: json.loads((Path(rec["report_dir"]) / "summary.json").read_text())
        for rec in records
    }
    _check_tables(out, summaries)
    # the database: a job per world and noise level, a done run per seed, the same figures
    with session_scope(env["DATABASE_URL"]) as s:
        jobs = s.scalars(select(Job)).all()
        assert len(jobs) == 4 and all(len(j.runs) == 2 and j.status == "done" for j in jobs)
        for rec in records:
            run = s.get(Run, rec["run_id"])
            assert run.status == "done" and run.summary["relations"] == rec["summary"]["relations"]
    page = (out / "report.html").read_text()
    for name in ("errors_by_world.png", "furniture.png", "noise.png", "a_vs_b.png"):
        assert (out / name).read_bytes()[:4] == b"\x89PNG" and f'alt="{name}"' in page
    assert "8 runs, 0 finished, 8 to do" in r.stderr


class CeleryService:
    """A fresh PostgreSQL database, a Redis database and one real `mapqual worker`."""

    def __init__(self, tmp: Path):
        admin_url = ensure_postgres()
        self.db_name = f"mapqual_batch_{uuid.uuid4().hex[:10]}"
        self.admin = create_engine(admin_url, isolation_level="AUTOCOMMIT")
        with self.admin.connect() as c:
            c.execute(text(f'CREATE DATABASE "{self.db_name}"'))
        self.db_url = admin_url.rsplit("/", 1)[0] + f"/{self.db_name}"
        self.redis_url = ensure_redis().rsplit("/", 1)[0] + f"/{REDIS_DB}"
        import redis

        self.broker = redis.Redis.from_url(self.redis_url)
        self.broker.flushdb()
        self.env = {"DATABASE_URL": self.db_url, "REDIS_URL": self.redis_url,
                    "MAPQUAL_RUNS_DIR": str(tmp / "worker_runs")}  # fmt: skip
        r = _mapqual(tmp, self.env, "db", "upgrade")
        assert r.returncode == 0, r.stderr
        self.log = open(tmp / "worker.log", "ab")  # noqa: SIM115 - closed in stop()
        self.worker = subprocess.Popen(
            [sys.executable, "-m", "mapqual", "worker", "--concurrency", "1"],
            env={**os.environ, **self.env}, stdout=self.log, stderr=self.log,
            start_new_session=True,
        )  # fmt: skip

    def stop(self) -> None:
        if self.worker.poll() is None:
            os.killpg(self.worker.pid, signal.SIGTERM)
            try:
                self.worker.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(self.worker.pid, signal.SIGKILL)
                self.worker.wait(timeout=10)
        self.log.close()
        self.broker.flushdb()
        get_engine(self.db_url).dispose()
        with self.admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{self.db_name}" WITH (FORCE)'))


@pytest.fixture(scope="module")
def celery_service(tmp_path_factory):
    svc = CeleryService(tmp_path_factory.mktemp("celery"))
    yield svc
    svc.stop()


def test_celery_batch_agrees_with_the_database_and_with_the_local_pool(
    worlds, local_batch, celery_service, tmp_path
):
    svc = celery_service
    r = _mapqual(tmp_path, svc.env, "batch", str(worlds), *ARGS, "--celery", "-o", "out")
    assert r.returncode == 0, r.stderr
    out = tmp_path / "out"
    records = [json.loads(p.read_text()) for p in out.glob("runs/*/record.json")]
    assert len(records) == 8
    with session_scope(svc.db_url) as s:
        runs = {rec["key"]: s.get(Run, rec["run_id"]) for rec in records}
        assert all(run.status == "done" for run in runs.values())
        summaries = {key: run.summary for key, run in runs.items()}
        assert len(s.scalars(select(Job)).all()) == 4
    _check_tables(out, summaries)
    # the worker ran the same runs as the local pool: the same figures, bit for bit
    local = {r["key"]: r for r in _csv(local_batch[0] / "out" / "runs.csv")}
    celery = {r["key"]: r for r in _csv(out / "runs.csv")}
    assert set(local) == set(celery)
    for key, row in celery.items():
        assert {k: row[k] for k in METRICS} == {k: local[key][k] for k in METRICS}
    for name in ("success.csv", "translation.csv", "rotation.csv"):
        assert (out / name).read_text() == (local_batch[0] / "out" / name).read_text()


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except FileNotFoundError:
        return []


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return False
    return state != "Z"


def _interrupt(tmp, env, args, sig, records_at_least):
    """Start the batch, wait until it has finished some runs and has others in flight, then
    send `sig` to the batch process alone; returns the keys finished at that moment."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "mapqual", "batch", *args], cwd=tmp, env={**os.environ, **env},
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    runs = tmp / "out" / "runs"
    deadline = time.monotonic() + 300
    while len(list(runs.glob("*/record.json"))) < records_at_least:
        assert proc.poll() is None, proc.stderr.read()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    workers = _children(proc.pid)
    os.kill(proc.pid, sig)
    proc.wait(timeout=60)
    done = {p.parent.name for p in runs.glob("*/record.json")}
    # the worker processes do not outlive the batch, however it was stopped
    deadline = time.monotonic() + 15
    while any(_alive(w) for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(_alive(w) for w in workers)
    return proc.returncode, done


def test_a_killed_batch_resumes_with_no_run_lost_or_done_twice(worlds, tmp_path):
    env = {"DATABASE_URL": f"sqlite:///{tmp_path / 'm.db'}"}
    args = [str(worlds / "rooms.yaml"), "--seeds", "1-6", "--slam", "odometry", "--laser-noise",
            "0.1", "--time-limit", "60", "--workers", "2", "-o", "out"]  # fmt: skip
    journal = tmp_path / "out" / "journal.jsonl"
    # SIGKILL: no clean-up at all; then SIGTERM: workers stopped, runs in flight requeued
    code, done1 = _interrupt(tmp_path, env, args, signal.SIGKILL, 2)
    assert code == -signal.SIGKILL and 2 <= len(done1) < 6
    n1 = len(journal.read_text().splitlines())
    code, done2 = _interrupt(tmp_path, env, args, signal.SIGTERM, len(done1) + 1)
    assert code == 130 and done1 < done2
    n2 = len(journal.read_text().splitlines())
    with session_scope(env["DATABASE_URL"]) as s:
        states = [r.status for r in s.scalars(select(Run))]
    assert "running" not in states  # SIGTERM requeued the runs it stopped
    r = _mapqual(tmp_path, env, "batch", *args)
    assert r.returncode == 0, r.stderr
    assert f"6 runs, {len(done2)} finished, {6 - len(done2)} to do" in r.stderr
    events = [json.loads(line) for line in journal.read_text().splitlines()]
    starts = [[e["key"] for e in part if e["event"] == "start"]
              for part in (events[:n1], events[n1:n2], events[n2:])]  # fmt: skip
    assert not set(starts[1]) & done1 and not set(starts[2]) & done2  # finished: not redone
    finished = [e["key"] for e in events if e["event"] in ("done", "error")]
    assert len(finished) == len(set(finished)) == 6  # each run finished exactly once
    assert {p.parent.name for p in (tmp_path / "out" / "runs").glob("*/record.json")} == set(
        finished
    )
    with session_scope(env["DATABASE_URL"]) as s:
        runs = s.scalars(select(Run)).all()
        assert len(runs) == 6 and {r.status for r in runs} == {"done"}
        assert sorted(r.seed for r in runs) == [1, 2, 3, 4, 5, 6]
    assert len(_csv(tmp_path / "out" / "runs.csv")) == 6


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.yaml"], "no such world file or folder"),
        (["w/rooms.yaml", "--runs", "2", "--seeds", "1-2"], "--runs or --seeds"),
        (["w/rooms.yaml", "--celery", "--workers", "2"], "--workers is for the local pool"),
        (["w/rooms.yaml", "--slam", "gmapping"], "slam"),
        (["--experiment", "nothing.yaml"], "no such experiment"),
        (["w/rooms.yaml", "--experiment", "thesis"], "not both"),
        (["w/rooms.yaml", "--only", "office*"], "matches none"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(worlds, tmp_path, args, message):
    (tmp_path / "w").symlink_to(worlds)
    r = _mapqual(tmp_path, {"DATABASE_URL": f"sqlite:///{tmp_path / 'm.db'}"}, "batch", *args)
    assert r.returncode == 2, r.stderr
    assert message in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_a_slice_of_the_thesis_experiment_dry_run(tmp_path):
    env = {"DATABASE_URL": f"sqlite:///{tmp_path / 'm.db'}"}
    r = _mapqual(tmp_path, env, "batch", "--experiment", "thesis", "--only", "office_d*",
                 "--runs", "2", "--dry-run", "-o", "out")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "8 runs, 0 finished, 8 to do" in r.stderr
    labels = sorted(line.split(None, 2)[2] for line in r.stdout.splitlines())
    # both variants at noise 0, and the noise sweep on office_d with furniture, 2 seeds each
    assert labels == sorted(
        f"{w} seed {s} rbpf noise {n}"
        for s in (1, 2)
        for w, n in [("office_d", "0"), ("office_d_furnitures", "0"),
                     ("office_d_furnitures", "0.1"), ("office_d_furnitures", "0.3")]
    )  # fmt: skip
    assert not (tmp_path / "out").exists()  # a dry run writes nothing


def test_a_killed_celery_batch_loses_nothing_and_sends_no_run_twice(
    worlds, celery_service, tmp_path
):
    svc = celery_service
    args = [str(worlds / "rooms.yaml"), "--seeds", "1-4", "--slam", "odometry", "--laser-noise",
            "0.1", "--time-limit", "40", "--celery", "-o", "out"]  # fmt: skip
    code, done = _interrupt(tmp_path, svc.env, args, signal.SIGKILL, 1)
    assert code == -signal.SIGKILL and len(done) < 4
    r = _mapqual(tmp_path, svc.env, "batch", *args)  # the worker carried on meanwhile
    assert r.returncode == 0, r.stderr
    events = [json.loads(line) for line in (tmp_path / "out" / "journal.jsonl").open()]
    sent = [e["run_id"] for e in events if e["event"] == "enqueued"]
    assert len(sent) == len(set(sent)) == 4  # each run sent to the queue once
    finished = [e["key"] for e in events if e["event"] in ("done", "error")]
    assert len(finished) == len(set(finished)) == 4
    with session_scope(svc.db_url) as s:
        runs = s.scalars(select(Run).where(Run.id.in_(sent))).all()
        assert len(runs) == 4 and {r.status for r in runs} == {"done"}
    assert len(_csv(tmp_path / "out" / "runs.csv")) == 4


def test_a_batch_retrains_the_prediction_model_on_its_runs(tmp_path):
    """--train-model: after the runs, the model of `mapqual predict` fitted on this batch's
    runs.csv and its worlds, written where asked and usable by `predict --model`."""
    folder = tmp_path / "worlds"
    folder.mkdir()
    for name, door in (("hall", 60), ("annex", 20), ("wing", 90)):  # three buildings
        img = np.full((120, 200), 255, np.uint8)
        img[[0, -1], :] = img[:, [0, -1]] = 0
        img[:, 100] = 0
        img[door : door + 20, 100] = 255
        Image.fromarray(img).save(folder / f"{name}.png")
        (folder / f"{name}.yaml").write_text(f"image: {name}.png\nresolution: 0.05\n")
    env = {"DATABASE_URL": f"sqlite:///{tmp_path / 'm.db'}"}
    args = ["--seeds", "1", "--slam", "odometry", "--time-limit", "20", "--workers", "2"]
    r = _mapqual(tmp_path, env, "batch", str(folder), *args, "-o", "out",
                 "--train-model", "model.json")  # fmt: skip
    assert r.returncode == 0, r.stderr
    model = json.loads((tmp_path / "model.json").read_text())
    assert sorted(model["training"]["worlds"]["odometry"]) == ["annex", "hall", "wing"]
    assert model["training"]["batches"] == ["out"] and "--train-model" in model["command"]
    assert "odometry leave-one-building-out" in r.stdout
    r = _mapqual(tmp_path, env, "predict", str(folder / "hall.yaml"), "--slam", "odometry",
                 "--model", "model.json", "--json")  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["b_mean_t"]["median"] > 0


def test_a_second_batch_on_a_folder_in_use_is_refused_and_changes_nothing(worlds, tmp_path):
    # two processes on one OUT would run the same runs twice and write each other's records
    # and jobs over (seen: "result not stored (run 54: cannot go to done from failed)")
    from worker.batch.state import BatchDir

    env = {"DATABASE_URL": f"sqlite:///{tmp_path / 'm.db'}"}
    args = ["batch", str(worlds / "rooms.yaml"), "--seeds", "1", "--slam", "odometry",
            "--time-limit", "20", "--workers", "1", "-o", "out"]  # fmt: skip
    out = BatchDir(tmp_path / "out")
    with out.lock():  # another batch process holds the folder
        r = _mapqual(tmp_path, env, *args)
        assert r.returncode == 2, r.stderr
        assert "is in use by another mapqual batch" in r.stderr
        assert f"(pid {os.getpid()})" in r.stderr and len(r.stderr.strip().splitlines()) == 1
        assert sorted(p.name for p in out.root.iterdir()) == [".lock"]  # nothing written
    r = _mapqual(tmp_path, env, *args)  # the lock goes with its holder
    assert r.returncode == 0, r.stderr
    assert len(_csv(out.root / "runs.csv")) == 1
