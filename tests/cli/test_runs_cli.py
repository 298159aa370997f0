"""`mapqual runs` and `mapqual db` as a user runs them: a real process on a real SQLite file."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

from backend.db.session import session_scope
from backend.store import (
    create_job,
    get_or_create_world,
    local_user,
    mark_run_started,
    store_run_result,
)
from tests.summaries import summary_doc
from worker.report.summary import RunSummary


def _mapqual(tmp_path, *args):
    env = dict(os.environ, DATABASE_URL=f"sqlite:///{tmp_path / 'm.db'}", COLUMNS="200")
    return subprocess.run(
        [sys.executable, "-m", "mapqual", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=120,
    )


def test_db_upgrade_creates_the_database(tmp_path):
    r = _mapqual(tmp_path, "db", "upgrade")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "m.db").exists()
    assert "database at head" in r.stdout


def test_runs_show_reads_back_a_stored_run(tmp_path):
    assert _mapqual(tmp_path, "db", "upgrade").returncode == 0
    url = f"sqlite:///{tmp_path / 'm.db'}"
    summary = summary_doc(outcome="failed", reason="collision", stop="collision", coverage=0.4)
    with session_scope(url) as s:
        w = get_or_create_world(
            s,
            owner_id=local_user(s).id,
            name="box",
            sha256="f" * 64,
            source_format="image",
            source_path=None,
            resolution=0.05,
            origin=(0, 0),
            occ=np.zeros((5, 5), bool),
            start_pose=(0, 0, 0),
            facts={},
        )
        run_id = (
            create_job(s, owner_id=w.owner_id, world_id=w.id, slam="rbpf", params={}, seeds=[4])
            .runs[0]
            .id
        )
        mark_run_started(s, run_id)
        z = np.zeros((3, 3))
        store_run_result(
            s,
            run_id,
            summary=RunSummary.model_validate(summary),
            t=np.arange(3.0),
            pose_gt=z,
            pose_est=z,
            map_ros=np.zeros((2, 2), np.int8),
            map_resolution=0.05,
            map_origin=(0, 0),
            report_dir="runs/1",
        )
    shown = _mapqual(tmp_path, "runs", "show", str(run_id), "--json")
    assert shown.returncode == 0, shown.stderr
    doc = json.loads(shown.stdout)
    assert doc["summary"] == summary and doc["seed"] == 4 and doc["status"] == "done"
    listed = json.loads(_mapqual(tmp_path, "runs", "list", "--json").stdout)
    assert [(r["id"], r["world"], r["outcome"], r["reason"]) for r in listed] == [
        (run_id, "box", "failed", "collision")
    ]
    table = _mapqual(tmp_path, "runs", "list")
    assert "collision" in table.stdout and "box" in table.stdout


def test_unknown_run_is_one_line_and_exit_code_2(tmp_path):
    r = _mapqual(tmp_path, "runs", "show", "999")
    assert r.returncode == 2
    assert r.stderr.strip() == "mapqual: error: no run with id 999"
