"""Estimates in: read from bags (PoseStamped, Odometry, tf chains), and the one-line checks of
clocks, frames and units against a hand-made ground truth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory
from worker.export import rosmsgs as m
from worker.export.checks import CheckParams, check_estimate
from worker.export.estimate import read_estimate

DT = 0.1


def _gt() -> Trajectory:
    """60 s along a figure of eight: 1 m/s, turning left then right (12 rad of turning)."""
    t = np.arange(601) * DT
    w = np.where(t < 30, 0.2, -0.2)
    th = np.concatenate([[0.0], np.cumsum(w[:-1] * DT)])
    x = 2.0 + np.concatenate([[0.0], np.cumsum(np.cos(th[:-1]) * DT)])
    y = 3.0 + np.concatenate([[0.0], np.cumsum(np.sin(th[:-1]) * DT)])
    return Trajectory(t, np.column_stack([x, y, th]))


def _write(path, fmt, topics):
    """A bag of `topics`: {topic: (msgtype, [(t, message)])}."""
    store = m.typestore(fmt)
    if fmt == "rosbag2":
        from rosbags.rosbag2 import StoragePlugin, Writer

        writer = Writer(path, version=8, storage_plugin=StoragePlugin.MCAP)
        ser = store.serialize_cdr
    else:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
        ser = store.serialize_ros1
    with writer:
        for topic, (msgtype, msgs) in topics.items():
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for t, msg in msgs:
                writer.write(conn, m.nanoseconds(t), ser(msg, msgtype))


def _pose_stamped(store, t, pose):
    g = store.types
    pos = g["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0)
    p = g["geometry_msgs/msg/Pose"](position=pos, orientation=m.quaternion(store, pose[2]))
    return g[m.POSE_STAMPED](header=m.header(store, t, "map"), pose=p)


@pytest.mark.parametrize("fmt", ["rosbag2", "rosbag1"])
def test_a_pose_stamped_topic_is_read_as_the_estimate(tmp_path, fmt):
    gt = _gt()
    store = m.typestore(fmt)
    odom = [
        (t, m.odometry(store, t, p + 1.0, (0, 0), "odom", "base_link"))
        for t, p in zip(gt.t, gt.poses, strict=True)
    ]
    est = [(t, _pose_stamped(store, t, p)) for t, p in zip(gt.t[::5], gt.poses[::5], strict=True)]
    out = tmp_path / ("b.bag" if fmt == "rosbag1" else "b")
    _write(out, fmt, {"/odom": (m.ODOMETRY, odom), "/slam_pose": (m.POSE_STAMPED, est)})
    traj = read_estimate(out)  # /odom is the sensor data: never taken for the estimate
    assert np.allclose(traj.t, gt.t[::5], atol=1e-9)
    assert np.allclose(traj.poses, gt.poses[::5], atol=1e-9)
    named = read_estimate(out, topic="/odom")
    assert np.allclose(named.poses[:, :2], gt.poses[:, :2] + 1.0, atol=1e-9)
    with pytest.raises(InputError, match="no topic /nope"):
        read_estimate(out, topic="/nope")


def test_tf_map_odom_composed_with_odom_base_link(tmp_path):
    """map -> odom a constant (1, -2, 90 degrees); odom -> base_link moving: map -> base_link is
    their product, written out by hand: R(90) [x, y] + (1, -2) = (1 - y, -2 + x), theta + pi/2."""
    store = m.typestore("rosbag2")
    t = np.arange(20) * DT
    ob = np.column_stack([0.3 * t, 0.1 * t, 0.05 * t])
    mo = np.array([1.0, -2.0, math.pi / 2])
    msgs = []
    for k in range(20):
        transforms = [m.transform(store, float(t[k]), ob[k], "odom", "base_link")]
        if k % 4 == 0:
            transforms.append(m.transform(store, float(t[k]), mo, "map", "odom"))
        msgs.append((float(t[k]), m.tf_message(store, transforms)))
    _write(tmp_path / "tf", "rosbag2", {"/tf": (m.TF, msgs)})
    traj = read_estimate(tmp_path / "tf")
    expect = np.column_stack([1.0 - ob[:, 1], -2.0 + ob[:, 0], ob[:, 2] + math.pi / 2])
    assert np.allclose(traj.poses, expect, atol=1e-9)


def test_the_same_motion_passes():
    gt = _gt()
    check_estimate(gt, gt, CheckParams())
    noisy = Trajectory(
        gt.t[::3], gt.poses[::3] + np.random.default_rng(1).normal(0, 0.01, (201, 3))
    )
    check_estimate(noisy, gt, CheckParams())
    # a first pose 1 s late (the slack of a 60 s run: 0.5 s + 1 % = 1.1 s) is fine
    check_estimate(Trajectory(gt.t[10:], gt.poses[10:]), gt, CheckParams())
    with pytest.raises(InputError, match="does not cover"):
        check_estimate(Trajectory(gt.t[12:], gt.poses[12:]), gt, CheckParams())


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        (lambda t, p: (t * 1000.0, p), "milliseconds instead of seconds"),
        (lambda t, p: (t * 1e9, p), "nanoseconds instead of seconds"),
        (lambda t, p: (t + 1.7e9, p), "shifted by 1.7e\\+09 s"),
        (lambda t, p: (t[:300], p[:300]), "does not cover the run"),
        (lambda t, p: (t, p + [0.0, 1.0, 0.0]), "1.000 m, 0.000 rad apart"),
        (lambda t, p: (t, p * [1.0, 1.0, 0.0] + [0.0, 0.0, 0.5]), "0.000 m, 0.500 rad apart"),
        (lambda t, p: (t, p * [1.0, 1.0, 180.0 / math.pi]), "degrees instead of radians"),
        (lambda t, p: (t, p * [1.0, -1.0, -1.0] + [0.0, 6.0, 0.0]), "mirrored frame"),
        (lambda t, p: (t, p * [1000.0, 1000.0, 1.0]), "millimetres .or centimetres. for metres"),
        (lambda t, p: (t, p * [1.0, 1.0, 1.0] + [1e7, 0.0, 0.0]), "not metres, or garbage"),
    ],
    ids=["ms", "ns", "epoch", "short", "offset", "rotated", "degrees", "mirrored", "mm", "far"],
)
def test_clock_frame_and_unit_mistakes_are_named(change, needle):
    gt = _gt()
    t, p = change(gt.t.copy(), gt.poses.copy())
    with pytest.raises(InputError, match=needle) as err:
        check_estimate(Trajectory(t, p), gt, CheckParams(), "slam_x")
    assert "\n" not in str(err.value) and str(err.value).startswith("slam_x: ")


def test_an_offset_frame_is_scored_when_asked():
    gt = _gt()
    check_estimate(Trajectory(gt.t, gt.poses + [5.0, 0.0, 0.0]), gt, CheckParams(frame=False))


def test_bare_storage_files_of_a_rosbag2_are_read(tmp_path):
    """A .db3 or .mcap alone (no metadata.yaml beside it), as users often pass them around."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    gt = _gt()
    store = m.typestore("rosbag2")
    for plugin, suffix in ((StoragePlugin.SQLITE3, ".db3"), (StoragePlugin.MCAP, ".mcap")):
        bag = tmp_path / f"b{suffix[1:]}"
        with Writer(bag, version=8, storage_plugin=plugin) as writer:
            conn = writer.add_connection("/pose", m.POSE_STAMPED, typestore=store)
            for t, p in zip(gt.t[::10], gt.poses[::10], strict=True):
                data = store.serialize_cdr(_pose_stamped(store, float(t), p), m.POSE_STAMPED)
                writer.write(conn, m.nanoseconds(float(t)), data)
        bare = tmp_path / f"alone{suffix}"
        bare.write_bytes(next(bag.glob(f"*{suffix}")).read_bytes())
        traj = read_estimate(bare)
        assert np.allclose(traj.poses, gt.poses[::10], atol=1e-9), suffix
