"""External SLAM in the closed loop of `run_one` on a tiny world: the example program explores
it, the twin reproduces the in-process run bit for bit, and a program killed, stalled or
answering garbage mid-run ends the run failed / slam_failed with nothing left running."""

from __future__ import annotations

import json
import os
import signal
import sys
import time

import numpy as np
import pytest

from tests.worker.slam.external.helpers import children, example, fake, twin
from tests.worker.test_pipeline import two_rooms
from worker.pipeline import RunCancelled, run_one
from worker.report.folder import write_report
from worker.run_params import RunParams
from worker.slam.gating import UpdateGate


def _params(command: list[str], **ext) -> RunParams:
    external = {"name": "prog", "command": command, **ext}
    return RunParams.from_json({"algorithm": "external", "slam": {"external": external}})


def test_the_example_program_explores_the_two_rooms_to_the_end(tmp_path):
    result = run_one(two_rooms(), _params(example()), 1)
    ex = result.exploration
    assert (ex.outcome, ex.reason) == ("completed", "no_frontier")
    assert ex.coverage > 0.9  # both rooms, as the in-process baseline maps them
    # dead reckoning: the map frame is the odometry frame, so the estimate drifts from the
    # truth only by the simulated odometry error (Stage's model: a few cm over ~10 m)
    err = np.hypot(*(ex.pose_est[:, :2] - ex.pose_gt[:, :2]).T)
    assert err[0] == 0.0 and 0.0 < err.max() < 0.5
    write_report(result, tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["params"]["slam"]["external"]["command"] == example()  # stored with the run
    assert summary["algorithm"] == "external:prog"  # the program by its name, in every table
    assert RunParams.from_json(summary["params"]) == result.params


def test_the_twin_reproduces_the_in_process_odometry_run_bit_for_bit():
    world = two_rooms()
    local = run_one(world, RunParams.from_json({"algorithm": "odometry"}), 4)
    remote = run_one(world, _params(twin("odometry")), 4)
    np.testing.assert_array_equal(remote.exploration.pose_est, local.exploration.pose_est)
    np.testing.assert_array_equal(remote.exploration.pose_gt, local.exploration.pose_gt)
    np.testing.assert_array_equal(
        remote.exploration.final_map.prob, local.exploration.final_map.prob
    )
    assert remote.summary.to_dict()["relations"] == local.summary.to_dict()["relations"]


def test_killing_the_program_mid_run_fails_the_run_as_slam_failed(tmp_path):
    pidfile = tmp_path / "pid"
    # the shell writes its pid and becomes the program (exec): the pid is the program's
    wrapper = ["/bin/sh", "-c", f'echo $$ > {pidfile}; exec "$0" "$@"', *example()]
    killed = []

    def kill_at_3s(p):
        if p.t >= 3.0 and not killed:
            pid = int(pidfile.read_text())
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    before = children()
    t0 = time.monotonic()
    result = run_one(two_rooms(), _params(wrapper), 1, on_progress=kill_at_3s)
    ex = result.exploration
    assert (ex.outcome, ex.reason) == ("failed", "slam_failed")
    assert "the program was killed by signal 9" in ex.stop_detail
    assert "| stderr: dead reckoning: 541 beams" in ex.stop_detail
    # the kill lands after the step of t = 3.0 s; the first step sent after it sees it: the
    # example asks for GMapping's gate, so that is the first step past the gate after 3.0 s
    # (pose_est is its odometry: dead reckoning), and the trajectory ends there
    sp = _params(wrapper).slam
    gate = UpdateGate(sp.linear_update, sp.angular_update, sp.temporal_update)
    sent = [k for k in range(len(ex.t)) if gate.step(ex.t[k], ex.pose_est[k]) and ex.t[k] > 3.0]
    step = sent[0] if sent else len(ex.t) - 1
    assert ex.stop_detail.startswith(
        f"external SLAM 'prog' failed at step {step} (t={ex.t[step]:.2f} s)"
    )
    assert len(ex.t) == step + 1 and ex.t[step] > 3.0
    assert time.monotonic() - t0 < 60 and children() == before
    assert not os.path.exists(f"/proc/{killed[0]}")
    write_report(result, tmp_path / "report")  # a failed run is reported like any other
    summary = json.loads((tmp_path / "report" / "summary.json").read_text())
    assert (summary["outcome"], summary["reason"]) == ("failed", "slam_failed")


@pytest.mark.parametrize(
    ("mode", "needle"),
    [
        ("garbage", "protocol error at step 12 (t=1.20 s): not a msgpack message"),
        ("stall", "failed at step 12 (t=1.20 s): the program took too long to answer"),
        ("crash", "failed at step 12 (t=1.20 s): the program exited with code 3"),
    ],
)
def test_a_program_failing_mid_run_ends_it_slam_failed_at_that_step(mode, needle):
    before = children()
    result = run_one(two_rooms(), _params(fake(mode, 12), step_timeout_s=1.0), 2)
    ex = result.exploration
    assert (ex.outcome, ex.reason) == ("failed", "slam_failed") and needle in ex.stop_detail
    assert len(ex.t) == 13 and children() == before
    # the last step keeps the last good estimate (dead reckoning: the odometry of step 11)
    np.testing.assert_array_equal(ex.pose_est[-1], ex.pose_est[-2])


def test_a_program_that_cannot_start_fails_the_run_at_its_first_step(tmp_path):
    result = run_one(two_rooms(), _params([sys.executable, "-c", "import sys; sys.exit(5)"]), 1)
    ex = result.exploration
    assert (ex.outcome, ex.reason) == ("failed", "slam_failed")
    assert "at start-up: the program exited with code 5" in ex.stop_detail
    assert len(ex.t) == 1
    write_report(result, tmp_path)
    assert json.loads((tmp_path / "summary.json").read_text())["reason"] == "slam_failed"


def test_a_cancelled_run_stops_its_program():
    before = children()

    def cancel_at_1s(p):
        if p.t >= 1.0:
            raise RunCancelled

    with pytest.raises(RunCancelled):
        run_one(two_rooms(), _params(example()), 1, on_progress=cancel_at_1s)
    assert children() == before
