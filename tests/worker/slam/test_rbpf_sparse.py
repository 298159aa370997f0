"""rbpf on a log that kept one scan every half metre or more (the corrected Radish logs): every
such scan is an update, and a wide climb finds a pose the fine one cannot reach."""

from __future__ import annotations

import numpy as np

from worker.slam.gating import UpdateGate
from worker.slam.params import SampledProposal, SlamParams
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

BOX = (0.0, 0.0, 8.0, 5.0)
QUIET = dict(srr=0.0, srt=0.0, str_=0.0, stt=0.0)  # no motion noise: particles at the odometry


def test_a_forced_step_is_an_update_and_restarts_the_sums():
    gate = UpdateGate(1.0, 0.25, -1.0)
    assert gate.step(0.0, np.zeros(3))  # the first scan
    assert not gate.step(1.0, np.array([0.1, 0.0, 0.0]))
    assert gate.step(2.0, np.array([0.1, 0.0, 0.0]), force=True)  # no motion, yet an update
    assert not gate.step(3.0, np.array([1.05, 0.0, 0.0]))  # 0.95 m since the forced update
    assert gate.step(4.0, np.array([1.1, 0.0, 0.0]))  # 1.0 m


def test_every_scan_of_a_sparse_log_is_an_update():
    laser = Laser()
    xs = 1.5 + 0.5 * np.arange(8)  # 0.5 m apart: less than linear_update, more than the substep
    slam = make_slam("rbpf", laser, SlamParams(particles=5), np.random.default_rng(0))
    for k, x in enumerate(xs):
        pose = np.array([x, 2.5, 0.0])
        slam.process(float(k), pose, box_scan(pose, laser.angles, BOX))
    assert slam.updates == len(xs)
    gmapping = make_slam(
        "rbpf", laser, SlamParams(particles=5, motion_substep=0.0, motion_substep_angle=0.0),
        np.random.default_rng(0),
    )  # fmt: skip
    for k, x in enumerate(xs):
        pose = np.array([x, 2.5, 0.0])
        gmapping.process(float(k), pose, box_scan(pose, laser.angles, BOX))
    assert gmapping.updates == 4  # the first scan, then every 1.0 m: x = 2.5, 3.5, 4.5


def _second_pose(params: SlamParams, odom_error: float) -> np.ndarray:
    """The estimate after two scans 0.6 m apart in x, the odometry's step odom_error too long."""
    laser = Laser()
    slam = make_slam("rbpf", laser, params, np.random.default_rng(0))
    first, second = np.array([2.0, 2.5, 0.0]), np.array([2.6, 2.5, 0.0])
    slam.process(0.0, first, box_scan(first, laser.angles, BOX))
    odom = second + np.array([odom_error, 0.0, 0.0])
    assert slam.process(1.0, odom, box_scan(second, laser.angles, BOX))
    return slam.pose_estimate()


def test_the_wide_climb_recovers_an_odometry_error_beyond_the_fine_window():
    # 0.3 m along x: the end walls' beams fall outside the fine 3 x 3 cell window (reach
    # 1.5 cells = 0.075 m), and the fine climb's 0.05 m first steps find no better score
    # beyond the corners' few beams; the wide 7 x 7 window (0.175 m) with 0.1 m steps does
    params = SlamParams(particles=1, linear_update=0.5, **QUIET)
    est = _second_pose(params, 0.3)
    assert abs(est[0] - 2.6) < 0.02 and abs(est[1] - 2.5) < 0.02 and abs(est[2]) < 0.01
    off = SlamParams(
        particles=1, linear_update=0.5, motion_substep=0.0, motion_substep_angle=0.0, **QUIET
    )
    assert abs(_second_pose(off, 0.3)[0] - 2.6) > 0.1  # GMapping's fine climb stays off


def test_the_proposals_prior_is_the_motion_model_in_each_particles_frame():
    # a 1 m step straight ahead is 7 substeps of 0.15 m: deviations srr 1 m, 0.3 srr 1 m and
    # srt 1 m over sqrt(7), i.e. variances 0.01 / 7 m^2 along the robot's heading, 0.0009 / 7
    # m^2 across it and 0.04 / 7 rad^2; the information matrix holds their inverses, along
    # map x for a particle heading 0, along map y for one heading pi/2, and for one heading
    # pi/4 both diagonals (700 + 7778) / 2 and the coupling (700 - 7778) / 2
    slam = make_slam(
        "rbpf", Laser(), SlamParams(particles=3, proposal=SampledProposal()),
        np.random.default_rng(0),
    )  # fmt: skip
    then = np.array([[1.0, 2.0, 0.0], [3.0, 1.0, np.pi / 2], [0.0, 0.0, np.pi / 4]])
    slam._at_update = (np.zeros(3), then)
    c, s = np.cos(then[:, 2]), np.sin(then[:, 2])
    pred = then + np.column_stack([c, s, np.zeros(3)])  # each 1 m along its heading
    info = slam._prior_information(pred)
    along, across, turn = 7 / 0.01, 7 / 0.0009, 7 / 0.04
    assert np.allclose(info[0], np.diag([along, across, turn]))
    assert np.allclose(info[1], np.diag([across, along, turn]))
    half_sum, half_diff = (along + across) / 2, (along - across) / 2
    expect = np.array([[half_sum, half_diff, 0], [half_diff, half_sum, 0], [0, 0, turn]])
    assert np.allclose(info[2], expect)


def test_the_sampled_proposal_leaves_a_10_hz_log_bit_for_bit():
    # steps of 0.05 m never reach motion_substep: no draw, no extra random number, the same run
    laser = Laser()
    xs = 1.5 + 0.05 * np.arange(40)
    runs = []
    for prop in (None, SampledProposal()):
        slam = make_slam(
            "rbpf", laser, SlamParams(particles=5, linear_update=0.2, proposal=prop),
            np.random.default_rng(4),
        )  # fmt: skip
        for k, x in enumerate(xs):
            pose = np.array([x, 2.5, 0.0])
            slam.process(0.1 * k, pose, box_scan(pose, laser.angles, BOX))
        runs.append((slam.poses.copy(), slam.log_weight_sums.copy(), slam.rng.random()))
    assert runs[0][2] == runs[1][2] and slam.updates > 5
    assert np.array_equal(runs[0][0], runs[1][0]) and np.array_equal(runs[0][1], runs[1][1])


def test_the_sampled_proposal_draws_around_the_match_on_a_sparse_step():
    # in the closed room every direction is held by a wall: the fitted Gaussian is narrow and
    # the drawn pose stays within the grid's +-0.1 m / +-0.01 rad of the true one
    laser = Laser()
    params = SlamParams(particles=5, proposal=SampledProposal())
    slam = make_slam("rbpf", laser, params, np.random.default_rng(0))
    for k, x in enumerate((2.0, 2.6, 3.2)):
        pose = np.array([x, 2.5, 0.0])
        assert slam.process(float(k), pose, box_scan(pose, laser.angles, BOX))
    assert np.all(np.abs(slam.poses[:, 0] - 3.2) < 0.1)
    assert np.all(np.abs(slam.poses[:, 1] - 2.5) < 0.1)
    assert np.all(np.abs(slam.poses[:, 2]) < 0.02)
