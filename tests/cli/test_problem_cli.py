"""`mapqual problem` and `mapqual slam` on the real corrected logs of ../shared/data/carmen:
the files, the degenerate CSAIL clock paired the same way for ground truth and estimate, and
one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.shared_data import CARMEN
from worker.evaluate.trajio import read_trajectory
from worker.sim.carmen import read_laser_log

DATA = CARMEN
needs_data = pytest.mark.skipif(not DATA.is_dir(), reason="no ../shared/data/carmen here")


@needs_data
def test_problem_writes_a_drifting_log_and_its_ground_truth(run, tmp_path):
    out = tmp_path / "aces"
    code, stdout, err = run(
        "problem", DATA / "aces-corrected.log.gz", "--seed", 4, "--scans", 60, "-o", out
    )
    assert code == 0, err
    summary = json.loads((out / "problem.json").read_text())
    assert summary["scans"] == 60 and summary["laser"]["range_max"] == 50.0
    gt = read_trajectory(out / "gt.tum")
    log = read_laser_log(out / "problem.log")
    real = read_laser_log(DATA / "aces-corrected.log.gz")
    np.testing.assert_allclose(gt.poses, real.pose_odom[:60], atol=1e-6)
    np.testing.assert_allclose(log.pose_gt, real.pose_odom[:60], atol=1e-6)
    np.testing.assert_allclose(log.ranges, real.ranges[:60], atol=5e-4)
    drift = np.hypot(*(log.pose_odom[-1, :2] - gt.poses[-1, :2]))
    assert 0.01 < drift < 5.0  # it drifts, by the size of a few percent of the path
    # same seed, same bytes
    code, _, err = run(
        "problem", DATA / "aces-corrected.log.gz", "--seed", 4, "--scans", 60, "-o", tmp_path / "b"
    )
    assert code == 0, err
    assert (tmp_path / "b" / "problem.log").read_bytes() == (out / "problem.log").read_bytes()


@needs_data
def test_the_coarse_csail_clock_pairs_ground_truth_and_estimate(run, tmp_path):
    # the odometry baseline's estimate is the log's own poses: paired right, every error is 0
    log = DATA / "csail-corrected.log.gz"
    code, _, err = run("slam", log, "--algorithm", "odometry", "-o", tmp_path / "odo")
    assert code == 0, err
    assert err.count("mapqual: warning:") == 1 and "cannot order the scans" in err
    est = read_trajectory(tmp_path / "odo" / "trajectory.tum")
    gt = read_trajectory(log)
    assert len(gt) == len(est) == 406
    np.testing.assert_allclose(est.t, gt.t, atol=1e-6)
    code, _, err = run("relations", log, "--kind", "A", "--dt", 20, "-o", tmp_path / "a.rel")
    assert code == 0, err
    code, stdout, err = run(
        "evaluate", "--relations", tmp_path / "a.rel", "--est", tmp_path / "odo/trajectory.tum",
        "--json", "--max-gap", 30,
    )  # fmt: skip
    assert code == 0, err
    summary = json.loads(stdout)
    assert summary["translation"]["n"] > 150  # the relations span the whole log
    assert summary["translation"]["max"] < 1e-5 and summary["rotation"]["max"] < 1e-5


def test_bad_input_is_one_line_and_exit_2(run, tmp_path):
    bad = tmp_path / "bad.log"
    bad.write_text("FLASER 3 1 2 x 0 0 0 0 0 0 1.0 h 1.0\nFLASER 3 1 2 3 0 0 0 0 0 0 2.0 h 2\n")
    code, _, err = run("problem", bad, "-o", tmp_path / "p")
    assert code == 2
    assert err.strip().splitlines() == [f"mapqual: error: {bad}:1: expected a number, got 'x'"]
    good = tmp_path / "good.log"
    good.write_text("FLASER 3 1 2 3 0 0 0 0 0 0 1.0 h 1\nFLASER 3 1 2 3 1 0 0 1 0 0 2.0 h 2\n")
    code, _, err = run("problem", good, "--scans", 5, "-o", tmp_path / "p")
    assert code == 2 and "the log has 2 scans" in err and len(err.strip().splitlines()) == 1
    code, _, err = run("problem", good, "--scale-std", 2, "-o", tmp_path / "p")
    assert code == 2 and "scale_std must be in [0, 1)" in err
