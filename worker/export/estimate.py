"""Read an estimate of a run's motion: TUM, CARMEN, or a ROS bag (PoseStamped, Odometry or tf).

In a bag (rosbag1 `.bag`, or a rosbag2 directory) the estimate is, unless a topic is named:
the first geometry_msgs/PoseStamped topic; else a nav_msgs/Odometry topic other than the
sensor data's own /odom and /ground_truth; else tf's map -> base_link, either published
directly or composed from map -> odom (interpolated at each odom -> base_link stamp) and
odom -> base_link.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from worker.errors import InputError
from worker.evaluate.trajectory import Trajectory
from worker.evaluate.trajio import read_trajectory
from worker.export.rosmsgs import ODOMETRY, POSE_STAMPED, TF, Frames, yaw_of
from worker.sim.carmen_lines import interpolate_poses

SENSOR_TOPICS = ("/odom", "/ground_truth")  # what `mapqual export` writes: never an estimate
BAG_SUFFIXES = (".bag", ".mcap", ".db3")


def is_bag(path: Path) -> bool:
    """A rosbag1 file or a rosbag2 directory (or one of its storage files)."""
    return path.is_dir() or path.suffix in BAG_SUFFIXES


def read_estimate(path: str | Path, fmt: str = "auto", topic: str | None = None,
                  frames: Frames | None = None) -> Trajectory:  # fmt: skip
    """The estimate in `path` as a Trajectory; `fmt` auto | tum | carmen | bag."""
    p = Path(path)
    if not p.exists():
        raise InputError("no such file", path=p)
    if fmt == "bag" or (fmt == "auto" and is_bag(p)):
        return read_bag_estimate(p, topic, frames or Frames())
    if topic is not None:
        raise InputError("--topic applies to a bag only", path=p)
    return read_trajectory(p, fmt)  # type: ignore[arg-type]


def _stamp(h: Any) -> float:
    return h.stamp.sec + 1e-9 * h.stamp.nanosec


def _bag_path(p: Path) -> Path:
    """The path AnyReader opens: a rosbag2's directory for one of its storage files."""
    return (
        p.parent if p.suffix in (".mcap", ".db3") and (p.parent / "metadata.yaml").is_file() else p
    )


def read_bag_estimate(path: Path, topic: str | None, frames: Frames) -> Trajectory:
    """The chosen topic's poses (see the module docstring), ordered by their header stamps."""
    from rosbags.highlevel import AnyReader, AnyReaderError

    try:
        with AnyReader([_bag_path(path)]) as reader:
            conns = _choose(reader.connections, topic, path)
            rows = [
                (reader.deserialize(raw, c.msgtype), c.msgtype)
                for c, _, raw in reader.messages(connections=conns)
            ]
    except InputError:
        raise
    except (AnyReaderError, Exception) as exc:  # noqa: BLE001 - any failure of a hostile file
        # a damaged or forged bag fails deep in the reader (struct, sqlite3, decompression,
        # KeyError on unknown types, ...): every one of them is the input's fault
        reason = f"{type(exc).__name__}: {exc}".splitlines()[0][:200]
        raise InputError(f"not a readable ROS bag ({reason})", path=path) from None
    if conns[0].msgtype == TF:
        return _tf_estimate([msg for msg, _ in rows], frames, path)
    t, poses = [], []
    for msg, msgtype in rows:
        pose = msg.pose.pose if msgtype == ODOMETRY else msg.pose
        t.append(_stamp(msg.header))
        poses.append((pose.position.x, pose.position.y, yaw_of(pose.orientation)))
    return _trajectory(t, poses, path, conns[0].topic)


def _choose(connections: list[Any], topic: str | None, path: Path) -> list[Any]:
    """The connections that carry the estimate."""
    if topic is not None:
        found = [c for c in connections if c.topic == topic]
        if not found:
            raise InputError(f"no topic {topic} in this bag", path=path)
        if found[0].msgtype not in (POSE_STAMPED, ODOMETRY, TF):
            raise InputError(
                f"{topic} is {found[0].msgtype}: not a pose, odometry or tf topic", path=path
            )
        return found
    for pick in (
        lambda c: c.msgtype == POSE_STAMPED,
        lambda c: c.msgtype == ODOMETRY and c.topic not in SENSOR_TOPICS,
        lambda c: c.msgtype == TF and c.topic == "/tf",
    ):
        found = [c for c in connections if pick(c)]
        if found:
            return [c for c in found if c.topic == found[0].topic]
    raise InputError(
        "no PoseStamped, Odometry (other than /odom, /ground_truth) or /tf topic in this bag",
        path=path,
    )


def _tf_estimate(messages: list[Any], frames: Frames, path: Path) -> Trajectory:
    """map -> base_link from /tf: published directly, or map -> odom composed with odom -> base."""
    tracks: dict[tuple[str, str], tuple[list[float], list[tuple[float, float, float]]]] = {}
    for msg in messages:
        for tf in msg.transforms:
            key = (tf.header.frame_id.lstrip("/"), tf.child_frame_id.lstrip("/"))
            tr, q = tf.transform.translation, tf.transform.rotation
            track = tracks.setdefault(key, ([], []))
            track[0].append(_stamp(tf.header))
            track[1].append((tr.x, tr.y, yaw_of(q)))
    direct = tracks.get((frames.map, frames.base))
    if direct is not None:
        return _trajectory(*direct, path, f"tf {frames.map} -> {frames.base}")
    m_o, o_b = tracks.get((frames.map, frames.odom)), tracks.get((frames.odom, frames.base))
    if m_o is None or o_b is None:
        raise InputError(
            f"/tf has no {frames.map} -> {frames.base}, nor {frames.map} -> {frames.odom} with "
            f"{frames.odom} -> {frames.base}",
            path=path,
        )
    t_mo, mo = _sorted(*m_o)
    t_ob, ob = _sorted(*o_b)
    correction = interpolate_poses(t_ob, t_mo, mo)  # map -> odom at each odometry stamp
    c, s = np.cos(correction[:, 2]), np.sin(correction[:, 2])
    poses = np.column_stack([
        correction[:, 0] + c * ob[:, 0] - s * ob[:, 1],
        correction[:, 1] + s * ob[:, 0] + c * ob[:, 1],
        correction[:, 2] + ob[:, 2],
    ])  # fmt: skip
    return _trajectory(t_ob.tolist(), poses.tolist(), path, "tf map -> odom -> base_link")


def _sorted(t: list[float], poses: list[Any]) -> tuple[np.ndarray, np.ndarray]:
    ta, pa = np.asarray(t, dtype=np.float64), np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    order = np.argsort(ta, kind="stable")
    return ta[order], pa[order]


def _trajectory(t: list[float], poses: list[Any], path: Path, what: str) -> Trajectory:
    if not t:
        raise InputError(f"{what}: no poses", path=path)
    ta, pa = _sorted(t, poses)
    return Trajectory.from_samples(ta, pa, path=path)
