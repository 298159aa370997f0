"""Reading CARMEN logs as real files hold them: every laser message, comments, no-return
readings, steps back in time, a coarse clock, a truncated last line (issue 17 section 1)."""

from __future__ import annotations

import gzip
import math

import numpy as np
import pytest

from worker.errors import InputError, InputWarning
from worker.sim.carmen import read_laser_log


def flaser(ranges, pose, t):
    r = " ".join(f"{v:g}" for v in ranges)
    p = " ".join(f"{v:g}" for v in pose)
    return f"FLASER {len(ranges)} {r} {p} {p} {t:.6f} pippo {t:.6f}\n"


def rawlaser(ranges, t, start=-1.5, res=0.5, max_range=8.0):
    r = " ".join(f"{v:g}" for v in ranges)
    fov = res * (len(ranges) - 1)
    return f"RAWLASER1 0 {start} {fov} {res} {max_range} 0.01 0 {len(ranges)} {r} 0 {t} h {t}\n"


def test_flaser_180_beams_over_180_degrees_and_the_largest_reading_is_no_return(tmp_path):
    # ACES: 180 beams, no return printed as 50
    path = tmp_path / "aces.log"
    scan = [50.0] * 90 + [2.5] * 90
    path.write_text(
        "# message formats defined: PARAM SYNC ODOM FLASER RLASER TRUEPOS\n"
        "PARAM robot_use_laser on nohost 0\n"
        "ODOM 0 0 0 0 0 0 0.11 pippo 0.11\n"
        + flaser(scan, [1.0, 2.0, 0.5], 21.0)
        + "NEFF 12.5\n"
        + flaser(scan[::-1], [1.5, 2.0, 0.6], 22.0)
    )
    log = read_laser_log(path)
    assert log.message == "FLASER" and log.ranges.shape == (2, 180)
    assert log.laser.range_max == 50.0  # the SLAM ignores readings >= 50 - 0.01
    assert log.laser.angle_min == -math.pi / 2
    assert log.laser.angle_increment == pytest.approx(math.pi / 180)
    np.testing.assert_allclose(log.pose_odom, [[1.0, 2.0, 0.5], [1.5, 2.0, 0.6]])


def test_rawlaser_geometry_and_pose_from_the_odom_lines(tmp_path):
    path = tmp_path / "raw.log"
    path.write_text(
        "ODOM 0 0 0 0 0 0 10.0 h 10.0\n"
        + rawlaser([1.0, 2.0, 8.0, 3.0, 4.0, 5.0, 6.0], 10.5, start=-1.5, res=0.5, max_range=8.0)
        + "ODOM 1 2 0.4 0 0 0 11.0 h 11.0\n"
        + "RAWLASER2 0 -1.5 3.0 0.5 8.0 0.01 0 2 1 1 0 10.7 h 10.7\n"  # another laser: skipped
    )
    log = read_laser_log(path)
    assert log.message == "RAWLASER1"
    assert (log.laser.n_beams, log.laser.angle_min, log.laser.angle_increment) == (7, -1.5, 0.5)
    assert log.laser.range_max == 8.0
    # halfway between the ODOM poses at 10.0 and 11.0
    np.testing.assert_allclose(log.pose_odom, [[0.5, 1.0, 0.2]])
    np.testing.assert_allclose(log.ranges[0], [1, 2, 8, 3, 4, 5, 6])


def test_robotlaser_reads_its_geometry_and_the_robot_pose(tmp_path):
    path = tmp_path / "robot.log"
    ranges = " ".join(["1.5"] * 5)
    # laser 0.2 m ahead of the robot, which faces +y
    path.write_text(
        f"ROBOTLASER1 0 -0.5 1.0 0.25 20.0 0.01 0 5 {ranges} 0 "
        "3.0 4.2 1.5707963 3.0 4.0 1.5707963 0.3 0.0 0.5 0.2 1.0 7.25 h 7.25\n"
    )
    log = read_laser_log(path)
    assert (log.laser.n_beams, log.laser.angle_min) == (5, -0.5)
    assert (log.laser.angle_increment, log.laser.range_max) == (0.25, 20.0)
    np.testing.assert_allclose(log.pose_odom, [[3.0, 4.0, 1.5707963]])
    assert log.t.tolist() == [7.25]


def test_scans_out_of_time_order_are_sorted_with_a_warning(tmp_path):
    path = tmp_path / "back.log"
    scan = [1.0] * 4
    path.write_text(
        flaser(scan, [0, 0, 0], 1.00)
        + flaser(scan, [1, 0, 0], 1.10)
        + flaser(scan, [2, 0, 0], 1.08)  # steps back by 0.02 s
        + flaser(scan, [2, 0, 0], 1.08)  # and is logged twice
        + flaser(scan, [3, 0, 0], 1.20)
    )
    with pytest.warns(InputWarning) as caught:
        log = read_laser_log(path)
    messages = sorted(str(w.message) for w in caught)
    assert any("1 exact duplicate scans dropped" in m for m in messages)
    assert any("1 scans out of time order: sorted (stable)" in m for m in messages)
    assert log.t.tolist() == [1.00, 1.08, 1.10, 1.20]
    assert log.pose_odom[:, 0].tolist() == [0, 2, 1, 3]


def test_a_coarse_clock_gives_the_index_clock_once(tmp_path):
    path = tmp_path / "csail.log"
    scan = [1.0] * 4
    lines = [flaser(scan, [k, 0, 0], 0).replace("0.000000", "1.13486e+09") for k in range(30)]
    lines += [flaser(scan, [30 + k, 0, 0], 0).replace("0.000000", "1.13487e+09") for k in range(3)]
    path.write_text("".join(lines))
    with pytest.warns(InputWarning, match="cannot order the scans") as caught:
        log = read_laser_log(path)
    assert len(caught) == 1
    assert log.pose_odom[:, 0].tolist() == list(range(33))  # file order
    np.testing.assert_allclose(np.diff(log.t), 1e4 / 32, atol=1e-6)


def test_a_truncated_last_line_is_skipped_with_a_warning(tmp_path):
    path = tmp_path / "cut.log"
    whole = flaser([1.0] * 4, [0, 0, 0], 1.0) + flaser([1.0] * 4, [1, 0, 0], 2.0)
    path.write_text(whole + "FLASER 4 1.0 1.0 1")  # cut off while written
    with pytest.warns(InputWarning, match=r"line 3 is truncated \(FLASER, 5 fields\): skipped"):
        log = read_laser_log(path)
    assert log.t.tolist() == [1.0, 2.0]


def test_a_gzip_log_cut_off_is_read_up_to_the_cut(tmp_path):
    path = tmp_path / "cut.log.gz"
    whole = "".join(flaser([1.0] * 4, [k, 0, 0], float(k)) for k in range(200))
    data = gzip.compress(whole.encode())
    path.write_bytes(data[: len(data) * 3 // 4])
    with pytest.warns(InputWarning, match="gzip data ends early"):
        log = read_laser_log(path)
    assert 10 < log.t.shape[0] < 200
    np.testing.assert_allclose(log.pose_odom[:, 0], np.arange(log.t.shape[0]))


def test_a_bad_line_that_is_not_the_last_names_its_line(tmp_path):
    path = tmp_path / "bad.log"
    good = flaser([1.0] * 4, [0, 0, 0], 1.0)
    path.write_text(good + "FLASER 4 1.0 1.0 1\n" + good.replace(" 1.000000", " 2.000000"))
    with pytest.raises(InputError, match=r"bad.log:2: FLASER line has 5 fields"):
        read_laser_log(path)


def test_a_bad_last_line_with_its_newline_is_an_error(tmp_path):
    path = tmp_path / "bad.log"
    path.write_text(flaser([1.0] * 4, [0, 0, 0], 1.0) + "FLASER 4 1.0 x 1.0 1.0 0 0 0 0 0 0 3\n")
    with pytest.raises(InputError, match=r"bad.log:2: expected a number, got 'x'"):
        read_laser_log(path)


def test_rawlaser_without_odom_is_an_error(tmp_path):
    path = tmp_path / "raw.log"
    path.write_text(rawlaser([1.0, 2.0], 3.0))
    with pytest.raises(InputError, match="RAWLASER1 scans carry no pose"):
        read_laser_log(path)


def test_a_cut_that_still_parses_is_found_by_its_length(tmp_path):
    # "ODOM 1 0 0 0 0 0 12.75 h 12.75" cut to "ODOM 1 0 0 0 0 0 1": a valid-looking line
    path = tmp_path / "cut.log"
    path.write_text(
        "ODOM 0 0 0 0 0 0 11.5 h 11.5\n" + flaser([1.0] * 4, [0, 0, 0], 12.0) + "ODOM 1 0 0 0 0 0 1"
    )
    with pytest.warns(InputWarning, match=r"line 3 is truncated \(ODOM, 8 fields\)"):
        log = read_laser_log(path)
    assert log.t_odom.tolist() == [11.5]


def test_a_largest_reading_held_once_is_a_real_return(tmp_path):
    # 2 x 180 readings, the largest (12.5 m) held once: under 0.1 %, so not a no-return value
    path = tmp_path / "room.log"
    scan = [2.0] * 179 + [12.5]
    path.write_text(flaser(scan, [0, 0, 0], 1.0) + flaser([2.0] * 180, [0.1, 0, 0], 2.0))
    assert read_laser_log(path).laser.range_max == 81.91
    far = [2.0] * 179 + [90.0]  # a longer-range laser: the maximum goes just above it
    path.write_text(flaser(far, [0, 0, 0], 1.0) + flaser([2.0] * 180, [0.1, 0, 0], 2.0))
    assert read_laser_log(path).laser.range_max == pytest.approx(90.02)
