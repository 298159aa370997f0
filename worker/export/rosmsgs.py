"""ROS message objects (rosbags typestores) of mapqual's arrays: LaserScan, Odometry, tf, Clock.

ROS 2 messages come from the Humble store (the same definitions in Jazzy for these types),
ROS 1 ones from Noetic; Noetic's store lacks tf2_msgs/TFMessage, which is registered here from
its one-line definition (its md5sum comes out as ROS's own, 94810edda583a504dfda3829e70d7eec).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any, Literal

import numpy as np

from worker.sim.laser import LaserSpec

BagFormat = Literal["rosbag2", "rosbag1"]

SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
TF = "tf2_msgs/msg/TFMessage"
CLOCK = "rosgraph_msgs/msg/Clock"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
_TF_MSG = "geometry_msgs/TransformStamped[] transforms\n"


@dataclass(frozen=True)
class Frames:
    """The frame ids of the bag (REP 105 names)."""

    map: str = "map"
    odom: str = "odom"
    base: str = "base_link"
    laser: str = "laser"


@cache
def typestore(fmt: BagFormat) -> Any:
    """The rosbags typestore of the bag format (ROS 2 Humble, or ROS 1 Noetic plus tf2_msgs)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if fmt == "rosbag2":
        return get_typestore(Stores.ROS2_HUMBLE)
    store = get_typestore(Stores.ROS1_NOETIC)
    store.register(get_types_from_msg(_TF_MSG, TF))
    return store


def stamp(store: Any, t: float) -> Any:
    """builtin_interfaces/Time of `t` [s] (t >= 0), rounded to the nanosecond."""
    ns = int(round(t * 1e9))
    return store.types["builtin_interfaces/msg/Time"](
        sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000
    )


def nanoseconds(t: float) -> int:
    """The bag record time of `t` [s]."""
    return int(round(t * 1e9))


def header(store: Any, t: float, frame_id: str, seq: int = 0) -> Any:
    """std_msgs/Header (ROS 1's has a sequence number)."""
    cls = store.types["std_msgs/msg/Header"]
    if "seq" in cls.__dataclass_fields__:
        return cls(seq=seq, stamp=stamp(store, t), frame_id=frame_id)
    return cls(stamp=stamp(store, t), frame_id=frame_id)


def quaternion(store: Any, theta: float) -> Any:
    """A rotation of `theta` [rad] about z."""
    q = store.types["geometry_msgs/msg/Quaternion"]
    return q(x=0.0, y=0.0, z=math.sin(0.5 * theta), w=math.cos(0.5 * theta))


def yaw_of(q: Any) -> float:
    """The heading [rad] of a geometry_msgs/Quaternion (any norm; roll and pitch ignored)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), q.w * q.w + q.x * q.x - q.y * q.y - q.z * q.z)


def laser_scan(store: Any, t: float, ranges_m: np.ndarray, laser: LaserSpec, scan_time: float,
               frame: str, seq: int = 0) -> Any:  # fmt: skip
    """sensor_msgs/LaserScan with the laser's geometry; no return (a reading at or past
    range_max) is +inf, as REP 117 asks."""
    ranges = np.asarray(ranges_m, dtype=np.float32).copy()
    ranges[ranges >= np.float32(laser.range_max)] = np.inf
    return store.types[SCAN](
        header=header(store, t, frame, seq),
        angle_min=float(laser.angle_min),
        angle_max=float(laser.angle_max),
        angle_increment=float(laser.angle_increment),
        time_increment=0.0,  # the whole scan at one instant, as the simulator takes it
        scan_time=float(scan_time),
        range_min=float(laser.range_min),
        range_max=float(laser.range_max),
        ranges=ranges,
        intensities=np.zeros(0, dtype=np.float32),
    )


def _pose(store: Any, pose: np.ndarray) -> Any:
    g = store.types
    position = g["geometry_msgs/msg/Point"](x=float(pose[0]), y=float(pose[1]), z=0.0)
    return g["geometry_msgs/msg/Pose"](position=position, orientation=quaternion(store, pose[2]))


def odometry(store: Any, t: float, pose: np.ndarray, twist_vw: tuple[float, float], frame: str,
             child: str, seq: int = 0) -> Any:  # fmt: skip
    """nav_msgs/Odometry: `pose` (3,) [x, y, theta] in `frame`, twist (v [m/s], w [rad/s]) in
    `child`; covariances zero (unknown)."""
    g = store.types
    zero36 = np.zeros(36, dtype=np.float64)
    vec = g["geometry_msgs/msg/Vector3"]
    twist = g["geometry_msgs/msg/Twist"](
        linear=vec(x=float(twist_vw[0]), y=0.0, z=0.0),
        angular=vec(x=0.0, y=0.0, z=float(twist_vw[1])),
    )
    return g[ODOMETRY](
        header=header(store, t, frame, seq),
        child_frame_id=child,
        pose=g["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(store, pose), covariance=zero36),
        twist=g["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=zero36.copy()),
    )


def transform(store: Any, t: float, pose: np.ndarray, parent: str, child: str) -> Any:
    """geometry_msgs/TransformStamped of `child` in `parent` (`pose` (3,) [x, y, theta])."""
    g = store.types
    translation = g["geometry_msgs/msg/Vector3"](x=float(pose[0]), y=float(pose[1]), z=0.0)
    tf = g["geometry_msgs/msg/Transform"](
        translation=translation, rotation=quaternion(store, pose[2])
    )
    return g["geometry_msgs/msg/TransformStamped"](
        header=header(store, t, parent), child_frame_id=child, transform=tf
    )


def tf_message(store: Any, transforms: list[Any]) -> Any:
    """tf2_msgs/TFMessage of the transforms."""
    return store.types[TF](transforms=transforms)


def clock(store: Any, t: float) -> Any:
    """rosgraph_msgs/Clock at `t` [s]."""
    return store.types[CLOCK](clock=stamp(store, t))


def body_twist(t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N, 2) [v, w] of an odometry track by backward differences: the displacement since the
    previous sample in the previous body frame over the time step (the first sample: zero)."""
    out = np.zeros((t.shape[0], 2))
    if t.shape[0] < 2:
        return out
    dt = np.diff(t)
    d = np.diff(poses[:, :2], axis=0)
    c, s = np.cos(poses[:-1, 2]), np.sin(poses[:-1, 2])
    forward = c * d[:, 0] + s * d[:, 1]
    dtheta = (np.diff(poses[:, 2]) + math.pi) % (2.0 * math.pi) - math.pi
    ok = dt > 0
    out[1:, 0] = np.where(ok, forward / np.where(ok, dt, 1.0), 0.0)
    out[1:, 1] = np.where(ok, dtheta / np.where(ok, dt, 1.0), 0.0)
    return out
