"""Write a run's (or any CARMEN log's) sensor data as a ROS bag: `write_bag`.

Topics: /scan (sensor_msgs/LaserScan, frame `laser`), /odom (nav_msgs/Odometry odom ->
base_link), /tf (the same odom -> base_link), /tf_static (base_link -> laser, once, latched /
transient-local: the mount ROBOTLASER1 lines give), /clock (rosgraph_msgs/Clock at every
scan) and /ground_truth (nav_msgs/Odometry of base_link in `map`, from TRUEPOS lines).
Stamps are the log's own times, so an estimate recorded from the bag scores against the run
with no clock shift (a log that starts before t = 0, which ROS time cannot hold, is shifted
to start at 0, and says so). ROS 2 bags use the MCAP storage (rosbag2 metadata version 8),
ROS 1 bags format 2.0.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from worker.errors import InputError
from worker.export import rosmsgs as m
from worker.sim.carmen import LaserLog, read_laser_log

SIM_LOG_NAMES = ("sim.log", "sim.log.gz")
ROSBAG2_VERSION = 8  # the oldest metadata version rosbags writes: read by more ROS 2 releases
TOPICS = {
    "scan": ("/scan", m.SCAN),
    "odom": ("/odom", m.ODOMETRY),
    "tf": ("/tf", m.TF),
    "tf_static": ("/tf_static", m.TF),
    "clock": ("/clock", m.CLOCK),
    "ground_truth": ("/ground_truth", m.ODOMETRY),
}
# At equal stamps: clock first (a player's sim time reaches t before t's data), then odometry
# and tf (a SLAM node looks the scan's pose up when the scan arrives), scan, ground truth. The
# record time (not the header stamp) of each is the stamp plus this many nanoseconds, because
# a bag player orders messages of equal record time by topic, not by their place in the file.


@dataclass(frozen=True)
class BagParams:
    """What the bag holds beyond the log: frame names and the laser's mount on the robot."""

    frames: m.Frames = field(default_factory=m.Frames)
    laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)  # [m, m, rad] laser in base_link


@dataclass(frozen=True)
class BagStats:
    """What was written: messages per topic and the time span."""

    path: Path
    format: m.BagFormat
    counts: dict[str, int]
    t_start: float  # [s]
    t_end: float  # [s]
    time_shift: float = 0.0  # [s] added to the log's times (a log that starts before t = 0)


def find_sim_log(source: str | Path) -> Path:
    """The CARMEN log of `source`: a run folder's sim.log(.gz), or the file itself."""
    src = Path(source)
    if src.is_dir():
        for name in SIM_LOG_NAMES:
            if (src / name).is_file():
                return src / name
        raise InputError("this run folder has no sim.log (the run was made without one)", path=src)
    if not src.is_file():
        raise InputError("no such run folder or log file", path=src)
    return src


def _streams(log: LaserLog, p: BagParams, store: Any) -> Iterator[tuple[int, int, str, Any]]:
    """Every message as (record time [ns], tie order, topic key, message), in time order."""
    f = p.frames
    t_odom, odom = (log.t_odom, log.odom) if log.t_odom.shape[0] else (log.t, log.pose_odom)
    twist = m.body_twist(t_odom, odom)
    scan_time = float(np.median(np.diff(log.t))) if log.t.shape[0] > 1 else 0.0
    offset = np.asarray(p.laser_offset, dtype=np.float64)

    def static() -> Iterator[tuple[int, int, str, Any]]:
        tf = m.transform(store, float(log.t[0]), offset, f.base, f.laser)
        yield m.nanoseconds(float(log.t[0])), 0, "tf_static", m.tf_message(store, [tf])

    def scans() -> Iterator[tuple[int, int, str, Any]]:
        for k in range(log.t.shape[0]):
            t = float(log.t[k])
            yield m.nanoseconds(t), 1, "clock", m.clock(store, t)
            msg = m.laser_scan(store, t, log.ranges[k], log.laser, scan_time, f.laser, k)
            yield m.nanoseconds(t), 4, "scan", msg

    def odometry() -> Iterator[tuple[int, int, str, Any]]:
        for k in range(t_odom.shape[0]):
            t, pose = float(t_odom[k]), odom[k]
            vw = (float(twist[k, 0]), float(twist[k, 1]))
            yield m.nanoseconds(t), 2, "odom", m.odometry(store, t, pose, vw, f.odom, f.base, k)
            tf = m.transform(store, t, pose, f.odom, f.base)
            yield m.nanoseconds(t), 3, "tf", m.tf_message(store, [tf])

    def ground_truth() -> Iterator[tuple[int, int, str, Any]]:
        if log.t_gt is None or log.pose_gt is None:
            return
        twist_gt = m.body_twist(log.t_gt, log.pose_gt)
        for k in range(log.t_gt.shape[0]):
            t = float(log.t_gt[k])
            vw = (float(twist_gt[k, 0]), float(twist_gt[k, 1]))
            msg = m.odometry(store, t, log.pose_gt[k], vw, f.map, f.base, k)
            yield m.nanoseconds(t), 5, "ground_truth", msg

    yield from heapq.merge(static(), scans(), odometry(), ground_truth(), key=lambda r: r[:2])


def _shifted(log: LaserLog) -> tuple[LaserLog, float]:
    """(the log, the shift [s] added to its times): none, unless it starts before t = 0, which
    ROS time cannot hold (some CARMEN logs count from a reference inside them); then it is
    moved to start at 0."""
    times = [log.t, log.t_odom] + ([log.t_gt] if log.t_gt is not None else [])
    first = min(float(x[0]) for x in times if x.shape[0])
    if first >= 0:
        return log, 0.0
    shift = -first
    t_gt = None if log.t_gt is None else log.t_gt + shift
    return dataclasses.replace(log, t=log.t + shift, t_odom=log.t_odom + shift, t_gt=t_gt), shift


def write_bag(
    log: LaserLog, out: str | Path, fmt: m.BagFormat, params: BagParams | None = None
) -> BagStats:
    """Write `log` as a bag at `out` (rosbag2: a directory holding metadata.yaml and one .mcap;
    rosbag1: one .bag file). `out` must not exist: the bag writers never overwrite."""
    p = params or BagParams()
    out = Path(out)
    if out.exists():
        raise InputError("exists already: choose a new output path", path=out)
    log, shift = _shifted(log)
    store = m.typestore(fmt)
    writer, conns, serialize = _open_writer(out, fmt, store)
    counts = dict.fromkeys(TOPICS, 0)
    try:
        for ns, tie, key, msg in _streams(log, p, store):
            writer.write(conns[key], ns + tie, serialize(msg, TOPICS[key][1]))
            counts[key] += 1
    except BaseException:
        writer.abort()  # both writers: close and leave no half-written bag open
        raise
    writer.close()
    spans = [log.t] + ([log.t_gt] if log.t_gt is not None else [])
    t0 = min(float(s[0]) for s in spans)
    t1 = max(float(s[-1]) for s in spans)
    return BagStats(out, fmt, counts, t0, t1, shift)


def _open_writer(out: Path, fmt: m.BagFormat, store: Any) -> tuple[Any, dict[str, Any], Any]:
    """(open writer, connection per topic key, serializer) of the format."""
    if fmt == "rosbag2":
        from rosbags.interfaces import (
            Qos,
            QosDurability,
            QosHistory,
            QosLiveliness,
            QosReliability,
            QosTime,
        )
        from rosbags.rosbag2 import StoragePlugin, Writer

        never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)
        latched = Qos(
            QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
            never, never, QosLiveliness.AUTOMATIC, never, False,
        )  # fmt: skip
        writer = Writer(out, version=ROSBAG2_VERSION, storage_plugin=StoragePlugin.MCAP)
        writer.open()
        conns = {
            key: writer.add_connection(
                topic,
                msgtype,
                typestore=store,
                offered_qos_profiles=[latched] if key == "tf_static" else [],
            )  # fmt: skip
            for key, (topic, msgtype) in TOPICS.items()
        }
        return writer, conns, store.serialize_cdr
    from rosbags.rosbag1 import Writer as Writer1

    writer = Writer1(out)
    writer.open()
    conns = {
        key: writer.add_connection(
            topic, msgtype, typestore=store, latching=1 if key == "tf_static" else None
        )
        for key, (topic, msgtype) in TOPICS.items()
    }
    return writer, conns, store.serialize_ros1


def laser_offset(path: str | Path) -> tuple[float, float, float]:
    """[m, m, rad] The laser's mount on the robot from the log's first ROBOTLASER1 line (its
    laser pose against its robot pose); zero for a log of other scan messages."""
    from worker.evaluate.textio import read_bytes
    from worker.sim.carmen_lines import parse_robotlaser

    data = read_bytes(path)  # what read_laser_log reads too (a .gz inflated)
    at = data.find(b"\nROBOTLASER1 ")
    if at < 0 and not data.startswith(b"ROBOTLASER1 "):
        return (0.0, 0.0, 0.0)
    start = 0 if at < 0 else at + 1
    end = data.find(b"\n", start)
    line = data[start : end if end >= 0 else len(data)].decode("utf-8", errors="replace")
    scan = parse_robotlaser(line.split(), str(path), 0)
    off = scan.laser_offset
    return (0.0, 0.0, 0.0) if off is None else (float(off[0]), float(off[1]), float(off[2]))


def export_bag(source: str | Path, out: str | Path, fmt: m.BagFormat,
               params: BagParams | None = None) -> BagStats:  # fmt: skip
    """Read the CARMEN log of `source` (a run folder or a log) and write it as a bag; by
    default base_link -> laser is the mount the log's ROBOTLASER1 lines give."""
    path = find_sim_log(source)
    log = read_laser_log(path)
    if params is None:
        params = BagParams(laser_offset=laser_offset(path))
    return write_bag(log, out, fmt, params)
