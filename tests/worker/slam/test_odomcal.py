"""Online odometry scale (worker.slam.odomcal) by hand, and as rbpf learns it on a sparse log."""

from __future__ import annotations

import numpy as np

from worker.slam.odomcal import OdomCalibration, ScaleEstimate
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

BOX = (0.0, 0.0, 8.0, 5.0)


def test_scale_is_the_least_squares_ratio_pulled_towards_one():
    est = ScaleEstimate(OdomCalibration(prior_m2=4.0, prior_rad2=4.0, limit=0.2))
    assert np.array_equal(est.scale, [1.0, 1.0, 1.0])
    for _ in range(4):
        est.add(np.array([1.0, 0.0, 0.5]), np.array([1.1, 0.0, 0.55]))
    # x: (4 + 4 * 1.1) / (4 + 4 * 1) = 1.05; theta: (4 + 4 * 0.275) / (4 + 4 * 0.25) = 1.02
    assert np.allclose(est.scale, [1.05, 1.0, 1.02])
    for _ in range(1000):
        est.add(np.array([1.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0]))
    assert est.scale[0] == 1.2  # clamped to 1 + limit


def test_rbpf_learns_the_scale_of_a_too_long_stride():
    laser = Laser()
    xs = 1.5 + 0.5 * np.arange(11)  # 0.5 m apart (sparse steps), odometry 10 % too long
    quiet = SlamParams(particles=1, srr=0.0, srt=0.0, str_=0.0, stt=0.0)
    slam = make_slam("rbpf", laser, quiet, np.random.default_rng(0))
    for k, x in enumerate(xs):
        pose = np.array([x, 2.5, 0.0])
        odom = np.array([1.5 + 1.1 * (x - 1.5), 2.5, 0.0])
        slam.process(float(k), odom, box_scan(pose, laser.angles, BOX))
        assert abs(slam.pose_estimate()[0] - x) < 0.02
    # ten matched steps of 0.5 m against 0.55 m of odometry, prior 4 m^2:
    # (4 + 10 * 0.5 * 0.55) / (4 + 10 * 0.55^2) = 6.75 / 7.025
    assert abs(slam._scale.scale[0] - 6.75 / 7.025) < 0.003
    assert slam._scale.scale[1] == 1.0 and slam._scale.scale[2] == 1.0
