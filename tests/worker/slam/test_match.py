"""The scan matcher recovers a known pose in a map built from closed-form scans."""

from __future__ import annotations

import numpy as np

from worker.slam.base import make_slam
from worker.slam.match_kernels import optimize, score_and_likelihood
from worker.slam.params import SlamParams

from .helpers import Laser, box_scan

BOX = (0.0, 0.0, 8.0, 5.0)
# an L-shaped obstacle inside the room breaks the rectangle's symmetry


def _mapped():
    laser = Laser()
    slam = make_slam("odometry", laser, SlamParams(linear_update=0, angular_update=0))
    for k, pose in enumerate([(2.0, 2.0, 0.0), (5.0, 3.0, 2.0), (6.5, 1.0, 3.0), (1.5, 4.0, -1)]):
        slam.process(float(k), np.array(pose), box_scan(pose, laser.angles, BOX))
    return laser, slam


def _score(slam, laser, pose, ranges, want_l=False):
    m = slam.maps
    a = laser.angles
    return score_and_likelihood(
        m.pool,
        m.bits,
        m.tables[0],
        m.tpx0,
        m.tpy0,
        *pose,
        ranges,
        np.cos(a),
        np.sin(a),
        0.05,
        30.0,
        29.99,
        0,
        1,
        0.05,
        0.075,
        want_l,
    )


def test_score_peaks_at_the_true_pose():
    laser, slam = _mapped()
    truth = np.array([3.3, 2.2, 0.4])
    ranges = box_scan(truth, laser.angles, BOX)
    s_true, l_true = _score(slam, laser, truth, ranges, True)
    # nearly every beam matches within a few millimetres: score ~ number of beams
    assert s_true > 0.95 * len(ranges)
    assert l_true > -0.2 * len(ranges)  # a few corner beams find no match (-0.5 / lsigma)
    for off in ([0.1, 0, 0], [0, -0.1, 0], [0, 0, 0.05]):
        s_off, l_off = _score(slam, laser, truth + np.array(off), ranges, True)
        assert s_off < s_true and l_off < l_true


def test_hill_climbing_recovers_the_pose():
    laser, slam = _mapped()
    m = slam.maps
    a = laser.angles
    truth = np.array([3.3, 2.2, 0.4])
    ranges = box_scan(truth, laser.angles, BOX)
    for off in ([0.12, -0.08, 0.04], [-0.1, 0.1, -0.05], [0.0, 0.0, 0.0]):
        start = truth + np.array(off)
        pose, score = optimize(
            m.pool,
            m.bits,
            m.tables[0],
            m.tpx0,
            m.tpy0,
            start,
            ranges,
            np.cos(a),
            np.sin(a),
            0.05,
            30.0,
            29.99,
            0,
            1,
            0.05,
            0.05,
            0.05,
            5,
        )
        assert np.hypot(*(pose[:2] - truth[:2])) < 0.025  # within half a map cell
        assert abs(pose[2] - truth[2]) < 0.01  # 3 cm at 3 m: the cell means limit it
        assert score >= _score(slam, laser, start, ranges)[0]
