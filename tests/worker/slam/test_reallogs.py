"""rbpf and the odometry baseline on short slices of the three corrected Radish logs (issue 17):
the problem of `worker.sim.drift` (3 % scale, 5 % per-step noise), scored by B relations."""

from __future__ import annotations

import numpy as np
import pytest

from tests.shared_data import CARMEN
from worker.evaluate.metric import evaluate_relations
from worker.evaluate.relations import BParams, relations_B
from worker.sim.carmen import read_laser_log
from worker.sim.drift import drifting_problem, log_slice
from worker.slam.params import SlamParams
from worker.slam.run import run_slam

DATA = CARMEN
TARGET_RATIO = 0.35  # issue 17: rbpf at most 0.35x the odometry baseline's mean B error


def mean_b_error(gt, est) -> float:
    params = BParams(min_relations=500)
    rel = relations_B(gt, est, np.random.default_rng(0), params)
    err = evaluate_relations(rel, est, params.max_gap)
    return float(err.translation[err.evaluated].mean())


@pytest.mark.skipif(not DATA.is_dir(), reason="no ../shared/data/carmen here")
@pytest.mark.parametrize(
    ("name", "scans"),
    [("aces", 150), ("csail", 150), ("freiburg-079", 300)],  # 150 m, 170 m and 30 m of path
)
@pytest.mark.filterwarnings("ignore:.*cannot order the scans")  # CSAIL's clock: tested apart
def test_rbpf_beats_dead_reckoning_on_a_slice(name, scans):
    log = log_slice(read_laser_log(DATA / f"{name}-corrected.log.gz"), 0, scans)
    problem, gt = drifting_problem(log, seed=0)
    errors = {}
    for algorithm in ("odometry", "rbpf"):
        result = run_slam(
            problem.t, problem.pose_odom, problem.ranges, problem.laser, algorithm,
            SlamParams(particles=20), np.random.default_rng(0),
        )  # fmt: skip
        errors[algorithm] = mean_b_error(gt, result.trajectory)
    assert errors["odometry"] > 0.3  # the odometry does drift
    assert errors["rbpf"] <= TARGET_RATIO * errors["odometry"], errors
