"""`write_bag`: every message read back with rosbags and compared with the CARMEN log it came from.

The log is written here with known poses and ranges, read back by `read_laser_log`, exported,
and the bag read with rosbags' own AnyReader. The expected values come from the log's text and
from ROS itself: REP 117's +inf for no return, the md5sums ROS 1 publishes for the message types.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.shared_data import SHARED
from worker.errors import InputError
from worker.export.bag import export_bag, write_bag
from worker.export.rosmsgs import body_twist
from worker.sim.carmen import CarmenWriter, read_laser_log
from worker.sim.laser import LaserSpec

N = 30
DT = 0.1
V, W = 0.5, 0.2  # [m/s], [rad/s] a constant arc


def _arc(t: np.ndarray, start=(2.0, 3.0, 0.3)) -> np.ndarray:
    """Poses along the arc of speed V and turn rate W from `start` (exact integration)."""
    x0, y0, th0 = start
    th = th0 + W * t
    r = V / W
    return np.column_stack(
        [x0 + r * (np.sin(th) - math.sin(th0)), y0 - r * (np.cos(th) - math.cos(th0)), th]
    )


@pytest.fixture(scope="module")
def log_path(tmp_path_factory):
    """A CARMEN log of N ticks: odometry drifting off the ground truth, every 7th beam no return."""
    path = tmp_path_factory.mktemp("log") / "sim.log"
    laser = LaserSpec()
    t = np.arange(N) * DT
    gt = _arc(t)
    odom = gt + np.column_stack([0.01 * t, -0.02 * t, 0.005 * t])
    rng = np.random.default_rng(0)
    with open(path, "w") as fh:
        w = CarmenWriter(fh, laser)
        for k in range(N):
            ranges = rng.uniform(0.5, 29.0, laser.n_beams)
            ranges[::7] = laser.range_max
            w.write_tick(float(t[k]), gt[k], odom[k], V, W, ranges)
    return path


def _lines(path, tag):
    return [ln.split() for ln in path.read_text().splitlines() if ln.startswith(tag + " ")]


def _read(bag):
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        conns = {c.topic: c for c in reader.connections}
        msgs = [
            (c.topic, ts, reader.deserialize(raw, c.msgtype)) for c, ts, raw in reader.messages()
        ]
    return conns, msgs


def _yaw(q) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def _stamp(h) -> float:
    if hasattr(h, "sec"):
        return h.sec + 1e-9 * h.nanosec
    return h.stamp.sec + 1e-9 * h.stamp.nanosec


@pytest.fixture(scope="module", params=["rosbag2", "rosbag1"])
def bag(request, log_path, tmp_path_factory):
    out = tmp_path_factory.mktemp("bag") / ("out.bag" if request.param == "rosbag1" else "out")
    stats = export_bag(log_path.parent, out, request.param)
    return request.param, stats, _read(out)


def test_every_topic_has_one_message_per_log_line(bag):
    fmt, stats, (conns, msgs) = bag
    assert stats.counts == {
        "scan": N,
        "odom": N,
        "tf": N,
        "tf_static": 1,
        "clock": N,
        "ground_truth": N,
    }
    types = {t: c.msgtype for t, c in conns.items()}
    assert types == {
        "/scan": "sensor_msgs/msg/LaserScan", "/odom": "nav_msgs/msg/Odometry",
        "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage",
        "/clock": "rosgraph_msgs/msg/Clock", "/ground_truth": "nav_msgs/msg/Odometry",
    }  # fmt: skip
    assert len(msgs) == 5 * N + 1
    if fmt == "rosbag1":  # the md5sums ROS 1 itself gives these types: a ROS node accepts them
        md5 = {t: c.digest for t, c in conns.items()}
        assert md5["/scan"] == "90c7ef2dc6895d81024acba2ac42f369"
        assert md5["/odom"] == "cd5e73d190d741a2f92e81eda573aca7"
        assert md5["/tf"] == "94810edda583a504dfda3829e70d7eec"
        assert md5["/clock"] == "a9c97c1d230cfc112e270351a944ee47"
        assert conns["/tf_static"].ext.latching == 1


def test_scans_carry_the_hokuyo_geometry_and_rep117_no_returns(bag, log_path):
    _, _, (_, msgs) = bag
    scans = [m for topic, _, m in msgs if topic == "/scan"]
    lines = _lines(log_path, "ROBOTLASER1")
    assert len(scans) == len(lines) == N
    for k, (msg, tok) in enumerate(zip(scans, lines, strict=True)):
        assert msg.header.frame_id == "laser"
        assert _stamp(msg.header) == pytest.approx(float(tok[-3]), abs=1e-9)
        # 541 beams over 270 degrees, half a degree apart: -135 to +135 degrees (float32 fields)
        assert msg.angle_min == pytest.approx(-3 * math.pi / 4, abs=1e-6)
        assert msg.angle_max == pytest.approx(3 * math.pi / 4, abs=1e-6)
        assert msg.angle_increment == pytest.approx(math.pi / 360, abs=1e-9)
        assert (msg.range_min, msg.range_max) == (0.0, 30.0)
        assert msg.scan_time == pytest.approx(DT)
        logged = np.array(tok[9 : 9 + 541], dtype=np.float64)
        no_return = logged >= 30.0
        assert no_return[::7].all() and no_return.sum() == len(range(0, 541, 7)), k
        assert np.isposinf(msg.ranges[no_return]).all()
        assert np.allclose(msg.ranges[~no_return], logged[~no_return], atol=1e-6)


def test_odometry_tf_and_ground_truth_are_the_logs_poses(bag, log_path):
    _, _, (_, msgs) = bag
    odom_lines, gt_lines = _lines(log_path, "ODOM"), _lines(log_path, "TRUEPOS")
    by_topic: dict[str, list] = {}
    for topic, _, m in msgs:
        by_topic.setdefault(topic, []).append(m)
    for k in range(N):
        o = [float(x) for x in odom_lines[k][1:4]]
        g = [float(x) for x in gt_lines[k][1:4]]
        msg = by_topic["/odom"][k]
        assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
        p = msg.pose.pose
        assert [p.position.x, p.position.y, _yaw(p.orientation)] == pytest.approx(o, abs=1e-9)
        tf = by_topic["/tf"][k].transforms[0]
        assert (tf.header.frame_id, tf.child_frame_id) == ("odom", "base_link")
        tr = tf.transform
        assert [tr.translation.x, tr.translation.y, _yaw(tr.rotation)] == pytest.approx(o, abs=1e-9)
        gmsg = by_topic["/ground_truth"][k]
        assert gmsg.header.frame_id == "map"
        gp = gmsg.pose.pose
        assert [gp.position.x, gp.position.y, _yaw(gp.orientation)] == pytest.approx(g, abs=1e-9)
        assert _stamp(msg.header) == pytest.approx(k * DT, abs=1e-9)
        c = by_topic["/clock"][k].clock
        assert c.sec + 1e-9 * c.nanosec == pytest.approx(k * DT, abs=1e-9)
    static = by_topic["/tf_static"][0].transforms[0]
    assert (static.header.frame_id, static.child_frame_id) == ("base_link", "laser")
    assert static.transform.translation.x == 0.0 and static.transform.rotation.w == 1.0


def test_at_each_instant_the_clock_and_the_pose_come_before_the_scan(bag):
    _, _, (_, msgs) = bag
    # grouped by header stamp, in the order a player plays them (the record times)
    order: dict[float, list[str]] = {}
    for topic, _, m in msgs:
        t = (
            _stamp(m.clock)
            if topic == "/clock"
            else _stamp((m.transforms[0] if "tf" in topic else m).header)
        )
        order.setdefault(round(t, 6), []).append(topic)
    assert order[0.0][:1] == ["/tf_static"]
    for topics in order.values():
        topics = [t for t in topics if t != "/tf_static"]
        assert topics == ["/clock", "/odom", "/tf", "/scan", "/ground_truth"]


def test_twist_of_an_arc_is_its_speed_and_turn_rate():
    t = np.arange(20) * DT
    vw = body_twist(t, _arc(t))
    # chord of the arc, projected on the previous heading: (V/W) sin(W dt), per dt
    assert vw[1:, 0] == pytest.approx((V / W) * math.sin(W * DT) / DT, abs=1e-12)
    assert vw[1:, 1] == pytest.approx(W, abs=1e-12)
    assert vw[0].tolist() == [0.0, 0.0]


def test_a_real_flaser_log_exports_with_its_180_degree_geometry(tmp_path):
    src = SHARED / "data" / "carmen" / "aces-corrected.log.gz"
    log = read_laser_log(src)
    stats = write_bag(log, tmp_path / "aces.bag", "rosbag1")
    assert stats.counts["scan"] == log.t.shape[0] > 100
    assert stats.counts["ground_truth"] == 0  # a corrected log has no TRUEPOS
    _, msgs = _read(tmp_path / "aces.bag")
    first = next(m for topic, _, m in msgs if topic == "/scan")
    # 180 FLASER beams: from -90 degrees, one degree apart (GMapping's reading of 180 beams)
    assert len(first.ranges) == 180
    assert first.angle_min == pytest.approx(-math.pi / 2)
    assert first.angle_increment == pytest.approx(math.pi / 180)
    assert first.angle_max == pytest.approx(-math.pi / 2 + 179 * math.pi / 180)


def test_refusals_are_one_line_input_errors(tmp_path, log_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(InputError, match="exists already"):
        export_bag(log_path, tmp_path / "taken", "rosbag2")
    with pytest.raises(InputError, match="no sim.log"):
        export_bag(tmp_path / "taken", tmp_path / "b", "rosbag2")


def test_a_log_starting_before_zero_is_shifted_to_zero(tmp_path, log_path):
    """ROS time has no negative stamps: a log from t = -1 s is moved by +1 s, and says so."""
    neg = tmp_path / "neg.log"
    lines = []
    for ln in log_path.read_text().splitlines():
        tok = ln.split()
        if tok and not tok[0].startswith("#"):
            t = float(tok[-1]) - 1.0
            tok[-3], tok[-1] = f"{t:.6f}", f"{t:.6f}"
            ln = " ".join(tok)
        lines.append(ln)
    neg.write_text("\n".join(lines) + "\n")
    stats = export_bag(neg, tmp_path / "n.bag", "rosbag1")
    assert stats.time_shift == pytest.approx(1.0)
    assert (stats.t_start, stats.t_end) == pytest.approx((0.0, (N - 1) * DT))
    _, msgs = _read(tmp_path / "n.bag")
    scans = [mm for topic, _, mm in msgs if topic == "/scan"]
    assert [_stamp(s.header) for s in scans] == pytest.approx(list(np.arange(N) * DT), abs=1e-9)


def test_the_laser_mount_of_robotlaser_lines_is_the_static_transform(tmp_path, log_path):
    """A log whose laser sits 0.2 m ahead of the robot centre, turned by 0.1 rad: its laser
    pose is robot pose (+) (0.2, 0, 0.1), written out by hand into every ROBOTLASER1 line."""
    lines = []
    for ln in log_path.read_text().splitlines():
        tok = ln.split()
        if tok and tok[0] == "ROBOTLASER1":
            k = 10 + int(tok[8]) + int(tok[9 + int(tok[8])])  # the laser pose's first field
            rx, ry, rth = (float(v) for v in tok[k + 3 : k + 6])
            laser = (rx + 0.2 * math.cos(rth), ry + 0.2 * math.sin(rth), rth + 0.1)
            tok[k : k + 3] = [f"{v:.6f}" for v in laser]
            ln = " ".join(tok)
        lines.append(ln)
    mounted = tmp_path / "mounted.log"
    mounted.write_text("\n".join(lines) + "\n")
    export_bag(mounted, tmp_path / "m.bag", "rosbag1")
    _, msgs = _read(tmp_path / "m.bag")
    static = next(mm for topic, _, mm in msgs if topic == "/tf_static").transforms[0]
    tr = static.transform
    assert [tr.translation.x, tr.translation.y, _yaw(tr.rotation)] == pytest.approx(
        [0.2, 0.0, 0.1], abs=2e-6
    )
