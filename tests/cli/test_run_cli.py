"""`mapqual run` as a user runs it: a real process, a real SQLite database, a real report.

The stored trajectories are re-evaluated here with a plain SE(2) implementation written for
this test, independent of worker.evaluate, and must reproduce the stored B figures.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from PIL import Image

from backend.db.session import session_scope
from backend.store import load_trajectory


def _png(path):
    img = np.full((120, 200), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:, 100] = 0
    img[50:70, 100] = 255
    Image.fromarray(np.flipud(img)).save(path)


def _mapqual(tmp_path, *args, timeout=600):
    env = dict(os.environ, DATABASE_URL=f"sqlite:///{tmp_path / 'm.db'}", COLUMNS="200")
    return subprocess.run(
        [sys.executable, "-m", "mapqual", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=timeout,
    )


def _pose_at(t, poses, q):
    i = int(np.argmin(np.abs(t - q)))
    assert abs(t[i] - q) < 1e-6
    return poses[i]


def _rel(a, b):
    """inv(a) b for SE(2) poses, written out by hand."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, b[2] - a[2]])


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("run")
    _png(tmp / "rooms.png")
    args = [
        "run",
        "rooms.png",
        "--resolution",
        "0.05",
        "--slam",
        "odometry",
        "--seed",
        "4",
        "--time-limit",
        "300",
        "--json",
        "-o",
        "report",
    ]
    params = tmp / "p.yaml"
    params.write_text("sim:\n  odom_model: gaussian\n  odom_sigmas: [0.05, 0.05, 0.05]\n")
    r = _mapqual(tmp, *args, "--params", str(params))
    assert r.returncode == 0, r.stderr
    return tmp, json.loads(r.stdout)


def test_run_writes_the_whole_report(finished_run):
    tmp, summary = finished_run
    report = tmp / "report"
    expected = {
        "summary.json",
        "map.pgm",
        "map.yaml",
        "map.png",
        "trajectories.png",
        "errors.png",
        "relations_B.txt",
        "relations_A.txt",
        "T.errors",
        "R.errors",
        "gt.log",
        "est.log",
        "gt.tum",
        "est.tum",
        "sim.log",
    }
    assert expected <= {p.name for p in report.iterdir()}
    on_disk = json.loads((report / "summary.json").read_text())
    assert on_disk["relations"] == summary["relations"]
    assert summary["outcome"] in ("completed", "failed", "incomplete")
    assert 0 <= summary["coverage"] <= 1
    assert summary["params"]["sim"]["odom_model"] == "gaussian"  # --params was applied
    assert set(summary["relations"]["B"]) == {"translation", "rotation", "skipped"}


def test_stored_trajectories_reproduce_the_stored_b_errors_independently(finished_run):
    tmp, summary = finished_run
    with session_scope(f"sqlite:///{tmp / 'm.db'}") as s:
        t, gt = load_trajectory(s, summary["run_id"], "gt")
        t2, est = load_trajectory(s, summary["run_id"], "est")
    assert np.array_equal(t, t2)
    rel = np.loadtxt(tmp / "report" / "relations_B.txt", ndmin=2)
    err_t, err_r = [], []
    for t1, tt2, x, y, _z, _r, _p, yaw in rel:
        # the relation file holds the ground-truth motion (to the file's 9 decimals)
        d_true = _rel(_pose_at(t, gt, t1), _pose_at(t, gt, tt2))
        assert np.allclose(d_true[:2], [x, y], atol=1e-8)
        d_est = _rel(_pose_at(t, est, t1), _pose_at(t, est, tt2))
        err_t.append(math.hypot(d_est[0] - x, d_est[1] - y))
        err_r.append(abs(math.remainder(d_est[2] - yaw, 2 * math.pi)))
    b = summary["relations"]["B"]
    assert b["translation"]["n"] == len(rel) > 0
    assert b["translation"]["mean"] == pytest.approx(np.mean(err_t), rel=1e-6, abs=1e-9)
    assert b["translation"]["max"] == pytest.approx(np.max(err_t), rel=1e-6, abs=1e-9)
    assert b["rotation"]["mean"] == pytest.approx(np.mean(err_r), rel=1e-6, abs=1e-9)


def test_mapqual_evaluate_on_the_report_files_reproduces_the_summary(finished_run):
    tmp, summary = finished_run
    r = _mapqual(
        tmp,
        "evaluate",
        "--relations",
        "report/relations_B.txt",
        "--est",
        "report/est.log",
        "--json",
    )
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)
    want = summary["relations"]["B"]
    for part in ("translation", "rotation"):
        for k in ("mean", "std", "min", "max", "n"):
            assert got[part][k] == pytest.approx(want[part][k], rel=1e-6, abs=1e-9), (part, k)


def test_rerun_makes_a_new_run_and_runs_show_reads_it(finished_run):
    tmp, summary = finished_run
    shown = json.loads(_mapqual(tmp, "runs", "show", str(summary["run_id"]), "--json").stdout)
    assert shown["summary"]["relations"] == summary["relations"]
    listed = json.loads(_mapqual(tmp, "runs", "list", "--json").stdout)
    assert summary["run_id"] in [r["id"] for r in listed]


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["run", "missing.yaml"], "no such file"),
        (["run", "rooms.png"], "resolution"),
        (["run", "rooms.png", "--resolution", "0.05", "--slam", "ekf"], "--slam"),
        (["run", "rooms.png", "--resolution", "0.05", "--params", "bad.yaml"], "unknown parameter"),
        (["run", "rooms.png", "--resolution", "0.05", "--realtime", "0"], "realtime.speed"),
        (["run", "rooms.png", "--resolution", "0.05", "--slam", "mrpt_icp"], "--slam"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(tmp_path, args, needle):
    _png(tmp_path / "rooms.png")
    (tmp_path / "bad.yaml").write_text("slam:\n  particle: 3\n")
    r = _mapqual(tmp_path, *args, timeout=120)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and needle in r.stderr


def test_a_lone_run_gives_the_scan_matcher_every_core_it_may_use(finished_run):
    _, summary = finished_run  # the environment left MAPQUAL_SLAM_THREADS unset
    assert summary["params"]["slam"]["threads"] == len(os.sched_getaffinity(0))
