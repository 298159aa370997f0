"""`mapqual export` and `mapqual score` as a user calls them, on a real run folder and database."""

from __future__ import annotations

import json

import pytest

from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import local_user
from backend.store.estimates import list_estimates
from tests.worker.export.runs import finished_run, store_run


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run") / "report"
    return folder, finished_run(folder)


@pytest.fixture
def db(monkeypatch, tmp_path):
    url = f"sqlite:///{tmp_path / 'm.db'}"
    monkeypatch.setenv("DATABASE_URL", url)
    from backend.core.config import get_settings

    get_settings.cache_clear()
    yield url
    get_settings.cache_clear()


def _ticks(folder) -> int:
    return sum(ln.startswith("TRUEPOS ") for ln in (folder / "sim.log").read_text().splitlines())


@pytest.mark.parametrize("fmt", ["rosbag1", "rosbag2"])
def test_export_writes_a_bag_of_every_tick(run, run_folder, tmp_path, fmt):
    from rosbags.highlevel import AnyReader

    folder, _ = run_folder
    out = tmp_path / ("r.bag" if fmt == "rosbag1" else "r")
    code, stdout, err = run("export", folder, "--format", fmt, "-o", out, "--json")
    assert code == 0, err
    doc = json.loads(stdout)
    n = _ticks(folder)
    assert doc["messages"]["scan"] == doc["messages"]["ground_truth"] == n
    with AnyReader([out]) as reader:
        assert {c.topic: c.msgcount for c in reader.connections}["/scan"] == n


def test_score_a_folder_and_a_stored_run_by_id(run, run_folder, db, tmp_path):
    folder, result = run_folder
    code, stdout, err = run(
        "score", folder, "--est", folder / "est.tum", "--name", "again", "--json"
    )
    assert code == 0, err
    doc = json.loads(stdout)
    assert doc["run_id"] is None  # a folder no database run owns: scored, not stored
    b = result.summary.relations["B"]
    assert doc["relations"]["B"]["translation"]["n"] == b.translation.n
    assert doc["relations"]["B"]["translation"]["mean"] == pytest.approx(
        b.translation.mean, abs=1e-8
    )
    upgrade(db)
    with session_scope(db) as s:
        owner = local_user(s).id
    run_id = store_run(db, owner, result, folder)
    bag = tmp_path / "b.bag"
    assert run("export", str(run_id), "-o", bag)[0] == 2  # export takes a folder or a log
    assert run("export", folder, "--format", "rosbag1", "-o", bag)[0] == 0
    code, stdout, err = run(
        "score", str(run_id), "--est", bag, "--topic", "/odom", "--name", "odom"
    )
    assert code == 0, err
    assert f"stored as algorithm 'odom' of run {run_id}" in stdout
    with session_scope(db) as s:
        rows = list_estimates(s, [run_id])
        assert [r.name for r in rows] == ["odom"]
        assert rows[0].b_mean_t == pytest.approx(b.translation.mean, abs=1e-5)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["export", "nowhere", "-o", "x.bag"], "no such run folder or log file"),
        (["export", "{folder}", "-o", "{folder}"], "exists already"),
        (["score", "{folder}", "--est", "nowhere.tum"], "no such file"),
        (["score", "{folder}", "--est", "{ms}"], "milliseconds instead of seconds"),
        (["score", "{folder}", "--est", "{short}"], "does not cover the run"),
        (["score", "{folder}", "--est", "{folder}/est.tum", "--name", "a/b"], "estimate name"),
        (
            ["score", "{folder}", "--est", "{folder}/est.tum", "--topic", "/x"],
            "--topic applies to a bag",
        ),
    ],
    ids=["no-source", "exists", "no-est", "ms", "short", "name", "topic"],
)
def test_bad_input_is_one_line_and_exit_code_2(run, run_folder, db, tmp_path, args, needle):
    folder, _ = run_folder
    rows = [ln for ln in (folder / "est.tum").read_text().splitlines() if not ln.startswith("#")]
    ms, short = tmp_path / "ms.tum", tmp_path / "short.tum"
    ms.write_text("".join(f"{float(r.split()[0]) * 1000} {r.split(' ', 1)[1]}\n" for r in rows))
    short.write_text("\n".join(rows[: len(rows) // 2]) + "\n")
    argv = [a.format(folder=folder, ms=ms, short=short) for a in args]
    code, _, err = run(*argv)
    assert code == 2
    assert err.count("\n") == 1 and needle in err, err
