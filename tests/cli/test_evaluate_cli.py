"""`mapqual relations`, `evaluate`, `ate`: outputs, files, and one-line errors with exit 2."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from worker.evaluate.metric import evaluate_relations
from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import read_relations, read_trajectory, write_carmen, write_tum


@pytest.fixture
def logs(tmp_path, rng):
    """Ground truth (CARMEN) and an estimate (TUM) that turns 0.03 rad wrong at t = 60 s."""
    n = 1500
    th = np.cumsum(rng.normal(0, 0.08, n))
    xy = np.cumsum(np.column_stack([np.cos(th), np.sin(th)]) * 0.08, axis=0)
    gt = Trajectory(np.arange(n) * 0.1, np.column_stack([xy, th]))
    est_p = gt.poses.copy()
    pivot = gt.poses[600]
    # rotate everything after sample 600 by 0.03 rad about the pose at 600
    c, s = math.cos(0.03), math.sin(0.03)
    rel = gt.poses[601:, :2] - pivot[:2]
    est_p[601:, 0] = pivot[0] + c * rel[:, 0] - s * rel[:, 1]
    est_p[601:, 1] = pivot[1] + s * rel[:, 0] + c * rel[:, 1]
    est_p[601:, 2] = gt.poses[601:, 2] + 0.03
    est = Trajectory(gt.t, est_p)
    write_carmen(tmp_path / "gt.log", gt)
    write_tum(tmp_path / "est.tum", est)
    return tmp_path / "gt.log", tmp_path / "est.tum"


def test_relations_every_kind_and_B_needs_est(run, logs, tmp_path):
    gt, est = logs
    for kind, extra in [("A", []), ("S", ["--dt", "5"]), ("M", []), ("SM", []), ("L", [])]:
        code, out, err = run("relations", gt, "--kind", kind, *extra, "-o", tmp_path / kind)
        assert code == 0, err
        n = len(read_relations(tmp_path / kind))
        assert out.strip() == f"wrote {n} {kind} relations to {tmp_path / kind}"
    code, out, err = run("relations", gt, "--kind", "B", "-o", tmp_path / "b.txt")
    assert code == 2 and out == ""
    assert err == (
        "mapqual: error: --kind B needs --est: the estimate's pilot errors set how many relations\n"
    )


def test_relations_B_same_seed_same_bytes(run, logs, tmp_path):
    gt, est = logs
    for name, seed in (("b1", 5), ("b2", 5), ("b3", 6)):
        code, _, err = run(
            "relations", gt, "--kind", "B", "--est", est, "--seed", seed, "-o", tmp_path / name
        )
        assert code == 0, err
    b1, b2, b3 = ((tmp_path / n).read_bytes() for n in ("b1", "b2", "b3"))
    assert b1 == b2 and b1 != b3


def test_relations_B_cap_warns_on_stderr(run, logs, tmp_path):
    gt, est = logs
    code, out, err = run(
        "relations", gt, "--kind", "B", "--est", est, "--max-relations", "10", "-o", tmp_path / "b"
    )
    assert code == 0
    assert err.startswith("mapqual: warning: B: (z s / E)^2 = ")
    assert "capped at max_relations = 10" in err
    assert len(read_relations(tmp_path / "b")) == 10


def test_option_for_another_kind_is_refused(run, logs, tmp_path):
    gt, _ = logs
    code, _, err = run("relations", gt, "--kind", "A", "--radius", "1", "-o", tmp_path / "x")
    assert code == 2 and err == "mapqual: error: --radius applies to --kind L, not A\n"


def test_evaluate_json_is_exactly_the_core_summary(run, logs, tmp_path):
    gt, est = logs
    run("relations", gt, "--kind", "B", "--est", est, "--seed", "1", "-o", tmp_path / "b.txt")
    code, out, err = run("evaluate", "--relations", tmp_path / "b.txt", "--est", est, "--json")
    assert code == 0, err
    assert out.count("\n") == 1
    got = json.loads(out)
    expect = evaluate_relations(read_relations(tmp_path / "b.txt"), read_trajectory(est)).summary()
    assert got == json.loads(json.dumps(expect))
    assert set(got) == {"translation", "rotation", "skipped"}
    assert got["rotation"]["max"] == pytest.approx(0.03, abs=1e-6)  # the one turn error


def test_evaluate_writes_error_files_and_table(run, logs, tmp_path):
    gt, est = logs
    run("relations", gt, "--kind", "A", "-o", tmp_path / "a.txt")
    out_dir = tmp_path / "out" / "run1"
    code, out, err = run("evaluate", "--relations", tmp_path / "a.txt", "--est", est, "-o", out_dir)
    assert code == 0, err
    assert "translation (m)" in out and "rotation (rad)" in out and "skipped: 0" in out
    summary = json.loads((out_dir / "summary.json").read_text())
    t_err = np.loadtxt(out_dir / "T.errors", ndmin=2)
    r_err = np.loadtxt(out_dir / "R.errors", ndmin=2)
    assert t_err.shape == (summary["translation"]["n"], 3) == r_err.shape
    assert t_err[:, 2].mean() == pytest.approx(summary["translation"]["mean"], abs=1e-9)
    assert r_err[:, 2].max() == pytest.approx(0.03, abs=1e-8)


def test_ate_json(run, logs):
    gt, est = logs
    code, out, err = run("ate", "--gt", gt, "--est", est, "--json")
    assert code == 0, err
    s = json.loads(out)
    assert s["translation"]["n"] == 1500 and s["skipped"] == 0
    assert 0 < s["translation"]["rmse"] < 5.0


def test_malformed_line_is_one_line_exit_2_no_traceback(tmp_path, logs):
    _, est = logs
    bad = tmp_path / "bad.txt"
    bad.write_text("# relations\n1.0 2.0 0.1 0 0 0 0 0.0\n3.0 4.0 0.1 0 0 0 0 zero\n")
    exe = Path(sys.executable).with_name("mapqual")
    proc = subprocess.run(
        [str(exe), "evaluate", "--relations", str(bad), "--est", str(est)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == (
        f"mapqual: error: {bad}:3: not a number: 'zero' (expected t1 t2 x y z roll pitch yaw)\n"
    )


def test_the_readme_example_reproduces_the_run_that_made_it(run):
    """examples/office_a (made by examples/make_examples.sh): `mapqual evaluate` on the shipped
    relations and estimate gives the B figures the run itself stored, and every relation is the
    ground-truth motion between the shipped gt.log poses."""
    ex = Path(__file__).resolve().parents[2] / "examples" / "office_a"
    code, out, _ = run(
        "evaluate", "--relations", ex / "relations_B.txt", "--est", ex / "est.log", "--json"
    )
    assert code == 0
    got = json.loads(out)
    want = json.loads((ex / "summary.json").read_text())["relations"]["B"]
    for part in ("translation", "rotation"):
        assert got[part]["n"] == want[part]["n"] > 0
        for stat in ("mean", "std", "min", "max"):
            assert got[part][stat] == pytest.approx(want[part][stat], rel=1e-6, abs=1e-9)
    gt = read_trajectory(ex / "gt.log")
    rel = np.loadtxt(ex / "relations_B.txt", ndmin=2)  # t1 t2 x y z roll pitch yaw
    for t1, t2, x, y, _z, _roll, _pitch, yaw in rel[:20]:
        a, b = (gt.poses[np.argmin(np.abs(gt.t - t))] for t in (t1, t2))
        c, s = math.cos(a[2]), math.sin(a[2])
        dx, dy = b[0] - a[0], b[1] - a[1]
        assert [c * dx + s * dy, -s * dx + c * dy] == pytest.approx([x, y], abs=1e-6)
        assert math.remainder(b[2] - a[2] - yaw, 2 * math.pi) == pytest.approx(0, abs=1e-6)
