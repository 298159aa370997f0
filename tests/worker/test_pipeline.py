"""run_one end to end on small purpose-built worlds: real simulator, SLAM and exploration."""

from __future__ import annotations

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.trajio import read_trajectory
from worker.pipeline import RunCancelled, run_one
from worker.report.folder import write_report
from worker.report.summary import RunSummary
from worker.run_params import RunParams
from worker.world.world import World


def two_rooms() -> World:
    """10 m x 6 m, two rooms joined by a 1 m door, a short wall in the left room."""
    occ = np.zeros((120, 200), bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    occ[:, 100] = True
    occ[50:70, 100] = False
    occ[60, 30:60] = True
    return World.from_array(occ, 0.05, name="two_rooms")


def _strip_wall_times(summary: RunSummary) -> dict:
    s = summary.to_dict()
    s.pop("timings")
    return s


def test_oracle_run_completes_covers_the_rooms_and_scores_zero(tmp_path):
    p = RunParams.from_json({"algorithm": "oracle", "explore": {"time_limit": 600.0}})
    r = run_one(two_rooms(), p, seed=3, sim_log=tmp_path / "sim.log")
    s = r.summary
    assert (s.outcome, s.reason, s.collision) == ("completed", None, None)
    assert s.coverage >= 0.95
    # the oracle's estimate is the ground truth: every relation error is zero
    assert np.array_equal(r.gt.poses, r.est.poses)
    assert s.relations["A"].translation.max == 0.0
    assert s.relations["A"].translation.n == pytest.approx(r.gt.t[-1] / 0.5, abs=1)
    # thesis rule: a pilot standard deviation of 0 asks for N = 0 B relations; the default
    # floor (eval.b.min_relations) draws 500, all with zero error and a zero half-width
    b = s.relations["B"].translation
    assert (b.n, b.max, b.ci95) == (500, 0.0, 0.0)
    # the CARMEN log has one ODOM, ROBOTLASER1 and TRUEPOS line per 10 Hz step
    lines = (tmp_path / "sim.log").read_text().splitlines()
    n = len(r.gt.t)
    assert sum(ln.startswith("ROBOTLASER1 ") for ln in lines) == n
    assert sum(ln.startswith("TRUEPOS ") for ln in lines) == n


def test_same_seed_same_run_bit_for_bit(tmp_path):
    p = RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 120.0}})
    a = run_one(two_rooms(), p, seed=11, sim_log=tmp_path / "a.log")
    b = run_one(two_rooms(), p, seed=11, sim_log=tmp_path / "b.log")
    assert _strip_wall_times(a.summary) == _strip_wall_times(b.summary)
    assert (tmp_path / "a.log").read_bytes() == (tmp_path / "b.log").read_bytes()
    c = run_one(two_rooms(), p, seed=12)
    assert not np.array_equal(a.gt.poses, c.gt.poses) or not np.array_equal(
        a.est.poses, c.est.poses
    )


def test_more_odometry_noise_gives_larger_b_errors():
    # dead reckoning with Gaussian odometry noise; 500 B relations at least, for stable means
    def b_mean(sigma: float) -> float:
        p = RunParams.from_json(
            {
                "algorithm": "odometry",
                "sim": {"odom_model": "gaussian", "odom_sigmas": [sigma, sigma, sigma]},
                "explore": {"time_limit": 300.0},
                "eval": {"b": {"min_relations": 500}},
            }
        )
        b = run_one(two_rooms(), p, seed=2).summary.relations["B"].translation
        assert b.n >= 500
        return b.mean

    low, high = b_mean(0.02), b_mean(0.2)
    assert 0 < low < high


def test_cancel_from_the_progress_callback_stops_the_run():
    seen = []

    def stop_after_5_s(prog):
        seen.append(prog.t)
        if prog.t >= 5.0:
            raise RunCancelled

    with pytest.raises(RunCancelled):
        run_one(two_rooms(), RunParams(algorithm="oracle"), 1, stop_after_5_s)
    assert 5.0 <= seen[-1] < 7.0


def test_bad_parameters_are_input_errors():
    with pytest.raises(InputError, match="algorithm"):
        RunParams.from_json({"algorithm": "ekf"})
    with pytest.raises(InputError, match="time_limit"):
        RunParams.from_json({"explore": {"time_limit": -5}})


def test_a_run_keeps_the_slams_final_trajectory_beside_its_online_estimate(tmp_path):
    # rbpf keeps its best particle's path (the final map's own): one pose per 10 Hz step, and
    # at the last step the same pose as the online estimate (both are the best particle's pose
    # at the last update, carried on by the same odometry); the odometry baseline keeps none
    p = RunParams.from_json(
        {
            "algorithm": "rbpf",
            "slam": {"particles": 5},
            "sim": {"odom_error": [0.05, 0.05, 0.1]},
            "explore": {"time_limit": 60.0},
        }
    )
    r = run_one(two_rooms(), p, seed=4)
    ex = r.exploration
    assert ex.pose_final is not None and ex.pose_final.shape == ex.pose_est.shape
    np.testing.assert_allclose(ex.pose_final[-1], ex.pose_est[-1], atol=1e-9)
    # resampling drops paths the online estimate followed: the two differ somewhere
    assert np.abs(ex.pose_final[:, :2] - ex.pose_est[:, :2]).max() > 1e-3
    # the report folder has it as est_final.tum beside est.tum
    write_report(r, tmp_path / "rbpf")
    final = read_trajectory(tmp_path / "rbpf" / "est_final.tum")
    np.testing.assert_allclose(final.t, ex.t, atol=1e-6)
    np.testing.assert_allclose(final.poses, ex.pose_final, atol=1e-6)
    odo = run_one(
        two_rooms(),
        RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 10.0}}),
        seed=4,
    )
    assert odo.exploration.pose_final is None
    write_report(odo, tmp_path / "odometry")
    assert not (tmp_path / "odometry" / "est_final.tum").exists()
