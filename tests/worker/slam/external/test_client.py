"""ExternalSlam against real child programs: the twin gives the in-process algorithm's answers,
and every way a program can fail ends in one SlamFailed naming the step, the child reaped."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.worker.slam.external.helpers import ROOT, children, fake, twin
from worker.errors import SlamFailed
from worker.sim.laser import LaserSpec
from worker.slam.external.client import ExternalSlam
from worker.slam.external.params import ExternalSlamParams
from worker.slam.odometry import OdometrySlam
from worker.slam.params import SlamParams

LASER = LaserSpec()


def _slam(command: list[str], **kw) -> ExternalSlam:
    ext = ExternalSlamParams("prog", tuple(command), **kw)
    return ExternalSlam(LASER, SlamParams(external=ext), np.random.default_rng(0))


def _scans(n: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """A robot driving and turning in a 4 m x 4 m box (ranges by hand: beams to the walls)."""
    angles = LASER.angles
    out = []
    for k in range(n):
        pose = np.array([-1.0 + 0.1 * k, 0.2, 0.05 * k])
        a = pose[2] + angles
        c, s = np.cos(a), np.sin(a)
        with np.errstate(divide="ignore"):
            tx = np.where(c > 0, (2 - pose[0]) / c, (-2 - pose[0]) / c)
            ty = np.where(s > 0, (2 - pose[1]) / s, (-2 - pose[1]) / s)
        out.append((0.1 * k, pose, np.minimum(np.abs(tx), np.abs(ty))))
    return out


def test_the_twin_answers_exactly_what_the_algorithm_in_process_gives():
    params = SlamParams(linear_update=0.3, angular_update=0.2)
    local = OdometrySlam(LASER, params)
    ext = ExternalSlamParams("twin", tuple(twin("odometry")))
    remote = ExternalSlam(LASER, replace(params, external=ext), np.random.default_rng(0))
    with remote:
        for t, pose, ranges in _scans(25):
            assert remote.process(t, pose, ranges) == local.process(t, pose, ranges)
            np.testing.assert_array_equal(remote.pose_estimate(), local.pose_estimate())
        a, b = remote.occupancy(), local.occupancy()
        np.testing.assert_array_equal(a.prob, b.prob)
        np.testing.assert_array_equal(a.origin, b.origin)
        assert remote.updates == local.updates > 3
        assert remote.program_name == "odometry (protocol twin)"
        pid = remote.pid
    assert remote.pid is None and not os.path.exists(f"/proc/{pid}")


@pytest.mark.parametrize(
    ("mode", "needle"),
    [
        ("garbage", "protocol error at step 3 (t=0.30 s): not a msgpack message"),
        ("print", "protocol error at step 3 (t=0.30 s): a frame of 1751477356 bytes announced"),
        ("seq", "protocol error at step 3 (t=0.30 s): the estimate answers seq 4, not 3"),
        ("nan", "protocol error at step 3 (t=0.30 s): 'pose' must be three finite numbers"),
        ("crash", "failed at step 3 (t=0.30 s): the program exited with code 3 | stderr: "),
        ("sigkill", "failed at step 3 (t=0.30 s): the program was killed by signal 9"),
        (
            "version3",
            "protocol error at start-up: the program speaks version 3; mapqual speaks 1 and 2",
        ),
    ],
)
def test_a_failing_program_is_one_slam_failed_that_names_the_step(mode, needle):
    before = children()
    slam = _slam(fake(mode, 3))
    with pytest.raises(SlamFailed) as info:
        for t, pose, ranges in _scans(6):
            slam.process(t, pose, ranges)
            np.testing.assert_array_equal(slam.pose_estimate(), pose)  # dead reckoning
    message = str(info.value)
    assert message.startswith("external SLAM 'prog' ") and needle in message
    assert "\n" not in message
    assert info.value.step == (None if mode == "version3" else 3)
    if mode == "crash":  # the stderr tail, in the message and in full
        assert message.endswith("| stderr: fake program: mode crash at step 3 | "
                                "matcher: segmentation fault in scan 42")  # fmt: skip
        assert info.value.stderr_tail.splitlines()[-1] == "matcher: segmentation fault in scan 42"
    assert children() == before  # stopped and reaped: no zombie
    np.testing.assert_array_equal(
        slam.pose_estimate(), [-0.8, 0.2, 0.1] if mode != "version3" else 0
    )
    with pytest.raises(SlamFailed):  # and it stays failed
        slam.process(1.0, np.zeros(3), np.ones(LASER.n_beams))


def test_a_stalled_program_times_out_and_is_killed():
    before = children()
    slam = _slam(fake("stall", 2), step_timeout_s=0.5)
    t0 = time.monotonic()
    with pytest.raises(SlamFailed, match=r"at step 2 \(t=0.20 s\): the program took too long to "
                                         r"answer \(time-out\)"):  # fmt: skip
        for t, pose, ranges in _scans(5):
            slam.process(t, pose, ranges)
    # 0.5 s to notice, 2 s (close_timeout_s) for it to exit after bye, then SIGKILL
    assert time.monotonic() - t0 < 10.0
    assert children() == before


def test_a_program_that_cannot_start_fails_at_start_up():
    slam = _slam(["/nonexistent/slam-program", "--x"])
    with pytest.raises(SlamFailed, match="failed at start-up: cannot start "
                                         "'/nonexistent/slam-program': No such file"):  # fmt: skip
        slam.process(0.0, np.zeros(3), np.ones(LASER.n_beams))


def test_a_failed_map_request_fails_the_next_scan():
    before = children()
    slam = _slam(fake("mapreq", 2))
    scans = _scans(4)
    for t, pose, ranges in scans[:3]:
        slam.process(t, pose, ranges)
    empty = slam.occupancy()  # asked for after step 2's update: garbage; the last map stays
    assert empty.shape == (1, 1) and children() == before
    with pytest.raises(SlamFailed, match=r"protocol error at step 2 \(t=0.20 s\): map request: "
                                         "not a msgpack message"):  # fmt: skip
        slam.process(*scans[3])


def _state(pid: int) -> str:
    """The process's state letter (R, S, Z, ...), or "gone"."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "gone"


def test_the_program_dies_with_the_worker_that_started_it(tmp_path):
    # a "worker" starts the program, which answers scan 0 and then sleeps in scan 1 (deaf to
    # its closed stdin); the worker prints the program's pid and is killed with SIGKILL, as a
    # hard time limit or the OOM killer would
    script = (
        "import sys, time, numpy as np\n"
        "from worker.slam.external.client import ExternalSlam\n"
        "from worker.slam.external.params import ExternalSlamParams\n"
        "from worker.slam.params import SlamParams\n"
        "from worker.sim.laser import LaserSpec\n"
        f"ext = ExternalSlamParams('p', tuple({fake('stall', 1)!r}), step_timeout_s=120.0)\n"
        "s = ExternalSlam(LaserSpec(), SlamParams(external=ext), np.random.default_rng(0))\n"
        "s.process(0.0, np.zeros(3), np.ones(LaserSpec().n_beams))\n"
        "print(s.pid, flush=True)\n"
        "s.process(0.1, np.zeros(3), np.ones(LaserSpec().n_beams))\n"
    )
    worker = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, cwd=ROOT)
    pid = int(worker.stdout.readline())
    time.sleep(0.5)  # the program is asleep in step 1 now
    assert _state(pid) in ("R", "S")
    worker.kill()
    worker.wait()
    deadline = time.monotonic() + 10  # the program would sleep for 60 s
    while _state(pid) in ("R", "S", "D") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert _state(pid) in ("Z", "X", "gone")  # killed (a zombie until init reaps it)


def test_a_gated_program_gets_only_the_scans_past_its_gate_with_the_odometry_between():
    """Steps of 0.1 m and a 0.25 m gate: the sums reach 0.3 m every third step, so steps 0, 3,
    6 and 9 are sent, each after two skipped ones (hand-derived); between them the pose is the
    program's last map -> odom correction composed with the odometry, as ROS's tf gives it."""
    scans = _scans(11)
    slam = _slam(fake("gate"))
    try:
        updated = [slam.process(t, odom, ranges) for t, odom, ranges in scans]
        pose = slam.pose_estimate()
        tail = slam._child.stderr_tail()
    finally:
        slam.close()
    assert not any(updated)  # the program never says its map changed
    got = [line for line in tail.splitlines() if line.startswith("got ")]
    assert got == ["got 0 trail 0", "got 3 trail 2", "got 6 trail 2", "got 9 trail 2"]
    x, y, th = scans[10][1]  # step 10, not sent: T = (1, 2, pi/2) (+) odometry by hand
    assert pose == pytest.approx([1.0 - y, 2.0 + x, np.pi / 2 + th], abs=1e-12)


def test_a_gate_with_a_negative_threshold_fails_at_start_up():
    slam = _slam(fake("badgate"))
    with pytest.raises(SlamFailed, match="linear_update and angular_update must be >= 0"):
        slam.process(*_scans(1)[0])
    slam.close()
