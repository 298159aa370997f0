"""Real-time emulation (worker.slam.realtime): hand-derived timing, dropped scans, the pose the
robot drives on while the SLAM is busy, and zero latency = the bare algorithm bit for bit."""

from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from tests.worker.slam.helpers import Laser, box_scan
from worker.errors import InputError
from worker.evaluate.se2 import compose
from worker.slam.params import SlamParams
from worker.slam.realtime import RBPF_C0, RBPF_C1, RealtimeSlam, update_cost_s
from worker.slam.realtime_params import RealtimeParams
from worker.slam.registry import make_slam

LASER = Laser(n_beams=181, angle_min=-math.pi / 2, angle_increment=math.pi / 180)
DT = 0.1


class EveryScan:
    """A SLAM that updates on every scan; its correction is (k, 0, 0) after its k-th update."""

    name = "odometry"

    def __init__(self):
        self.k = 0
        self.odom = np.zeros(3)
        self.fed: list[float] = []

    def process(self, t, pose_odom, ranges_m) -> bool:
        self.k += 1
        self.odom = np.asarray(pose_odom, dtype=float)
        self.fed.append(t)
        return True

    def T_map_odom(self):
        return np.array([float(self.k), 0.0, 0.0])

    def pose_estimate(self):
        return compose(self.T_map_odom(), self.odom)

    def occupancy(self):
        return ("map", self.k)


def drive(slam, n: int):
    """Feed n scans at 10 Hz, driving 0.1 m/step along x turning 0.01 rad/step; the
    (pose estimate, odometry, map) after each."""
    out = []
    for k in range(n):
        odom = np.array([0.1 * k, 0.0, 0.01 * k])
        slam.process(k * DT, odom, np.full(LASER.n_beams, 3.0))
        out.append((slam.pose_estimate(), odom, slam.occupancy()))
    return out


@pytest.mark.parametrize("latency,expected_kept", [(0.25, 34), (0.1, 100), (0.35, 25), (1.0, 10)])
def test_busy_slam_drops_the_scans_that_arrive_meanwhile(latency, expected_kept):
    # an update on the scan at t is busy until t + L: scans before are dropped, the first at or
    # after is processed; with updates on every scan that keeps one scan in ceil(L / dt)
    # (hand count for L = 0.25: 0.0 kept, 0.1 0.2 dropped, 0.3 kept, ... 34 of 100)
    inner = EveryScan()
    rt = RealtimeSlam(inner, RealtimeParams(fixed_latency_s=latency), LASER.n_beams)
    drive(rt, 100)
    assert rt.stats.updates == expected_kept == len(inner.fed)
    assert rt.stats.dropped == 100 - expected_kept
    step = math.ceil(round(latency / DT, 9))
    np.testing.assert_allclose(inner.fed, DT * step * np.arange(expected_kept), atol=1e-9)
    assert rt.stats.latencies == [latency] * expected_kept


def test_the_robot_drives_on_the_last_published_pose_and_map():
    inner = EveryScan()
    rt = RealtimeSlam(inner, RealtimeParams(fixed_latency_s=0.25), LASER.n_beams)
    seen = drive(rt, 7)
    # update 1 on scan 0 publishes at 0.3 (scan 3), update 2 on scan 3 at 0.6 (scan 6); before
    # a publication the pose is the last published correction (k - 1, 0, 0) x current odometry
    published = [0, 0, 0, 1, 1, 1, 2]
    for (est, odom, grid), k in zip(seen, published, strict=True):
        want = compose(np.array([float(k), 0.0, 0.0]), odom) if k else odom
        np.testing.assert_allclose(est, want, atol=1e-12)
        if k:
            assert grid == ("map", k)
    assert rt.stats.dropped == 4


def test_zero_latency_is_the_bare_algorithm_bit_for_bit():
    angles = LASER.angles
    poses = [np.array([1.0 + 0.05 * k, 2.0 + 0.02 * k, 0.03 * k]) for k in range(120)]
    params = SlamParams(particles=8, linear_update=0.2, angular_update=0.1)
    bare = make_slam("rbpf", LASER, params, np.random.default_rng(3))
    rt = RealtimeSlam(
        make_slam("rbpf", LASER, params, np.random.default_rng(3)),
        RealtimeParams(fixed_latency_s=0.0), LASER.n_beams,
    )  # fmt: skip
    for k, p in enumerate(poses):
        ranges = box_scan(p, angles)
        assert bare.process(k * DT, p, ranges) == rt.process(k * DT, p, ranges)
        assert bare.pose_estimate().tobytes() == rt.pose_estimate().tobytes()
    assert bare.occupancy().prob.tobytes() == rt.occupancy().prob.tobytes()
    assert rt.stats.dropped == 0 and rt.stats.updates == bare.updates


def test_a_slower_computer_drops_more_scans_never_fewer():
    angles = LASER.angles
    poses = [np.array([1.0 + 0.08 * k, 2.0 + 0.01 * k, 0.02 * k]) for k in range(80)]
    params = SlamParams(particles=30, linear_update=0.1, angular_update=0.05)
    dropped = []
    for speed in (1.0, 0.3, 0.1, 0.03, 0.01):
        rt = RealtimeSlam(
            make_slam("rbpf", LASER, params, np.random.default_rng(0)),
            RealtimeParams(speed=speed), LASER.n_beams,
        )  # fmt: skip
        for k, p in enumerate(poses):
            rt.process(k * DT, p, box_scan(p, angles))
        dropped.append(rt.stats.dropped)
        # the modelled latency, by hand: c0 + c1 * particles * beams * (iterations + 1), / speed
        want = (RBPF_C0 + RBPF_C1 * 30 * 181 * (params.iterations + 1)) / speed
        assert rt.stats.latencies == pytest.approx([want] * rt.stats.updates)
    assert dropped == sorted(dropped) and dropped[-1] > dropped[0]


def test_cost_model_and_params_refuse_what_they_cannot_time():
    with pytest.raises(InputError):
        RealtimeParams(speed=0.0)
    with pytest.raises(InputError):
        RealtimeParams(speed=math.inf)
    with pytest.raises(InputError):
        RealtimeParams(fixed_latency_s=-1.0)

    class Unknown:
        name = "mystery"

    with pytest.raises(InputError, match="no real-time cost model"):
        update_cost_s(Unknown(), 10)


@pytest.mark.parametrize("latency", [0.05, 0.25, 0.7])
def test_the_update_in_a_worker_thread_gives_the_run_made_in_place(latency):
    # rbpf splits its update (advance / update): in a worker thread, joined at publication,
    # every pose, correction, map read and count is the one the update made in place gives
    angles = LASER.angles
    params = SlamParams(particles=10, linear_update=0.15, angular_update=0.05)
    poses = [np.array([1.0 + 0.06 * k, 2.0 + 0.015 * k, 0.025 * k]) for k in range(90)]
    runs = {}
    for background in (True, False):
        rt = RealtimeSlam(
            make_slam("rbpf", LASER, params, np.random.default_rng(7)),
            RealtimeParams(fixed_latency_s=latency), LASER.n_beams, background=background,
        )  # fmt: skip
        seen = []
        for k, p in enumerate(poses):
            out = rt.process(k * DT, p, box_scan(p, angles))
            seen.append((out, rt.pose_estimate().tobytes(), rt.T_map_odom().tobytes()))
            if k % 3 == 0:  # the map the navigation reads, mid-update or not
                seen.append(rt.occupancy().prob.tobytes())
        seen.append(rt.occupancy_with_hits().prob.tobytes())
        rt.close()
        runs[background] = (seen, rt.stats)
    assert runs[True][0] == runs[False][0]
    assert runs[True][1] == runs[False][1]
    assert runs[True][1].dropped > 0 or latency < DT


class SlowSplit(EveryScan):
    """EveryScan split in two; `update` waits until the test lets it finish."""

    def __init__(self):
        super().__init__()
        self.release = threading.Event()
        self.finished = threading.Event()

    def advance(self, t, pose_odom, ranges_m):
        self.odom = np.asarray(pose_odom, dtype=float)
        self.fed.append(t)
        return ranges_m

    def update(self, ranges):
        assert self.release.wait(10.0)
        self.k += 1
        self.finished.set()
        return True


def test_the_held_back_update_runs_beside_the_caller_and_is_joined_at_publication():
    inner = SlowSplit()
    rt = RealtimeSlam(inner, RealtimeParams(fixed_latency_s=0.25), LASER.n_beams)
    odom = np.zeros(3)
    ranges = np.full(LASER.n_beams, 3.0)
    # scan 0 starts the update and returns while it is still being computed: the caller drives
    # on (scans 1 and 2 dropped) on the snapshot from before it, map and pose
    rt.process(0.0, odom, ranges)
    rt.process(0.1, odom, ranges)
    rt.process(0.2, odom, ranges)
    assert not inner.finished.is_set() and inner.k == 0
    np.testing.assert_array_equal(rt.pose_estimate(), odom)
    assert rt.occupancy() == ("map", 0)
    inner.release.set()
    # its publication time (0.3 s) joins it: published, and the next update started
    assert rt.process(0.3, odom, ranges) is True
    assert inner.finished.is_set() and rt.stats.dropped == 2
    rt.close()
    assert inner.k == 2
