"""`score_estimate` on a real run: the run's own relation files, errors written out by hand."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import read_relations, read_trajectory
from worker.export.bag import export_bag
from worker.export.checks import CheckParams
from worker.export.estimate import read_estimate
from worker.export.score import score_estimate


def _rel(a, b):
    """inv(a) b for SE(2) poses, written out by hand."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, b[2] - a[2]])


def _hand_errors(rel, est: Trajectory):
    """Translational and rotational errors on relations whose times are samples of `est`."""
    index = {round(float(t), 6): k for k, t in enumerate(est.t)}
    et, er = [], []
    for t1, t2, d in zip(rel.t1, rel.t2, rel.delta, strict=True):
        x1, x2 = est.poses[index[round(float(t1), 6)]], est.poses[index[round(float(t2), 6)]]
        de = _rel(x1, x2)
        et.append(math.hypot(de[0] - d[0], de[1] - d[1]))
        er.append(abs((de[2] - d[2] + math.pi) % (2 * math.pi) - math.pi))
    return np.array(et), np.array(er)


def test_a_perturbed_estimate_scores_as_the_hand_computed_errors(run_folder, tmp_path):
    folder, result = run_folder
    gt = read_trajectory(folder / "gt.tum")
    rng = np.random.default_rng(7)
    est = Trajectory(gt.t, gt.poses + rng.normal(0.0, [0.05, 0.05, 0.01], gt.poses.shape))
    score = score_estimate(folder, est, "noisy", "noisy.tum", out_dir=tmp_path / "noisy")
    for kind in ("B", "A", "SM"):
        rel = read_relations(folder / f"relations_{kind}.txt")
        et, er = _hand_errors(rel, est)
        s = score.summary["relations"][kind]
        assert s["translation"]["n"] == len(rel) == result.summary.relations[kind].translation.n
        if len(rel):
            assert s["translation"]["mean"] == pytest.approx(et.mean(), abs=1e-9)
            assert s["rotation"]["mean"] == pytest.approx(er.mean(), abs=1e-9)
            assert s["translation"]["max"] == pytest.approx(et.max(), abs=1e-9)
    assert len(result.relations["B"]) > 10  # the run has B relations to compare on


def test_the_runs_own_estimate_scores_as_the_run(run_folder, tmp_path):
    folder, result = run_folder
    score = score_estimate(folder, read_trajectory(folder / "est.tum"), "again", "est.tum")
    assert score.folder == folder / "estimates" / "again"
    for kind in ("B", "A", "SM"):
        ours = result.summary.relations[kind]
        s = score.summary["relations"][kind]
        assert s["translation"]["n"] == ours.translation.n
        if ours.translation.n:  # est.tum has 9 decimals: the same figures to 1e-8
            assert s["translation"]["mean"] == pytest.approx(ours.translation.mean, abs=1e-8)
            assert s["rotation"]["mean"] == pytest.approx(ours.rotation.mean, abs=1e-8)
    names = sorted(p.name for p in score.folder.iterdir())
    assert names == [
        "R.errors", "T.errors", "errors.png", "est.log", "est.tum", "summary.json",
        "trajectories.png",
    ]  # fmt: skip
    doc = json.loads((score.folder / "summary.json").read_text())
    assert doc["name"] == "again" and doc["run"]["algorithm"] == "odometry"
    lines = (score.folder / "T.errors").read_text().splitlines()
    assert len(lines) == result.summary.relations["B"].translation.n


def test_a_rigidly_moved_estimate_has_the_same_relation_errors(run_folder, tmp_path):
    """d = inv(X1) X2 cancels a constant frame offset: scored when the frame check is off."""
    folder, _ = run_folder
    est = read_trajectory(folder / "est.tum")
    c, s = math.cos(0.7), math.sin(0.7)
    p = est.poses
    moved = np.column_stack(
        [c * p[:, 0] - s * p[:, 1] + 3.0, s * p[:, 0] + c * p[:, 1] - 1.0, p[:, 2] + 0.7]
    )
    a = score_estimate(folder, est, "a", "a", out_dir=tmp_path / "a")
    with pytest.raises(InputError, match="frame offset or rotated"):
        score_estimate(folder, Trajectory(est.t, moved), "b", "b", out_dir=tmp_path / "b")
    b = score_estimate(
        folder,
        Trajectory(est.t, moved),
        "b",
        "b",
        checks=CheckParams(frame=False),
        out_dir=tmp_path / "b",
    )
    for kind in ("B", "A"):
        ta, tb = (
            a.summary["relations"][kind]["translation"],
            b.summary["relations"][kind]["translation"],
        )
        assert tb["mean"] == pytest.approx(ta["mean"], abs=1e-9) and tb["n"] == ta["n"]


def test_the_odometry_played_from_the_runs_bag_scores_as_the_odometry_run(run_folder, tmp_path):
    """The run's algorithm is dead reckoning: its estimate is the odometry, which the bag's
    /odom carries (to the log's 6 decimals)."""
    folder, result = run_folder
    export_bag(folder, tmp_path / "bag", "rosbag2")
    est = read_estimate(tmp_path / "bag", topic="/odom")
    score = score_estimate(folder, est, "from_bag", "bag", out_dir=tmp_path / "s")
    ours = result.summary.relations["B"]
    s = score.summary["relations"]["B"]
    assert s["translation"]["n"] == ours.translation.n
    assert s["translation"]["mean"] == pytest.approx(ours.translation.mean, abs=1e-5)
    assert s["rotation"]["mean"] == pytest.approx(ours.rotation.mean, abs=1e-5)


def test_bad_names_and_folders_are_refused(run_folder, tmp_path):
    folder, _ = run_folder
    est = read_trajectory(folder / "est.tum")
    for bad in ("../up", "", ".hidden", "a b", "x" * 41):
        with pytest.raises(InputError, match="estimate name"):
            score_estimate(folder, est, bad, "s")
    with pytest.raises(InputError, match="no summary.json"):
        score_estimate(tmp_path, est, "ok", "s")
