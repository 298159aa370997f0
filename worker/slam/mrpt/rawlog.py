"""MRPT rawlogs in the action / sensory-frame form, written without MRPT.

MRPT's `rbpf-slam` and `icp-slam` read a rawlog as pairs: a CActionCollection (the odometry
increment since the previous scan, CActionRobotMovement2D) then a CSensoryFrame (the scan,
CObservation2DRangeScan). `carmen2rawlog` writes the other form, observations only, which
rbpf-slam 2.5 cannot read (it dereferences the missing action: SIGSEGV) and which icp-slam
reads through its odometry's time stamps. The byte layout follows MRPT 2.5's serialization
(CArchive::WriteObject and each class's serializeTo, all little-endian):

    object := u8 (0x80 | len(name)), name, u8 version, fields..., u8 0x88
    time stamp := u64, 100 ns ticks since 1601-01-01 (mrpt::Clock)
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import BinaryIO

import numpy as np

from worker.evaluate.se2 import compose, inverse

_END = b"\x88"  # SERIALIZATION_END_FLAG
_UNIX_EPOCH_TICKS = 116_444_736_000_000_000  # 1970-01-01 in 100 ns ticks since 1601-01-01
# CActionRobotMovement2D's Gaussian motion model (MRPT's defaults: a1 0.01, a2 0.001 deg->rad
# written as RAD2DEG(0.001), a3 1 deg, a4 0.05, minStdXY 0.01 m, minStdPHI 0.2 deg)
GAUSSIAN_MODEL = (0.01, math.degrees(0.001), math.radians(1.0), 0.05, 0.01, math.radians(0.2))
# the Thrun model's fields, written but unused with the Gaussian model (MRPT's defaults)
_THRUN = (300, 0.05, math.radians(4.0), 0.01, math.degrees(0.0001), 0.001, math.radians(0.05))


def ticks(t: float) -> int:
    """An mrpt::Clock time stamp of `t` seconds since 1970 (the log's own t, kept as is)."""
    return _UNIX_EPOCH_TICKS + int(round(t * 1e7))


def _obj(name: str, version: int, body: bytes) -> bytes:
    raw = name.encode("ascii")
    return bytes([0x80 | len(raw)]) + raw + bytes([version]) + body + _END


def _pose2d(p: np.ndarray) -> bytes:
    return _obj(
        "mrpt::poses::CPose2D", 1, struct.pack("<3d", float(p[0]), float(p[1]), float(p[2]))
    )


def _pose3d_yaw(yaw: float) -> bytes:
    # CPose3D v3: x, y, z, then the rotation matrix row by row (a turn about z)
    c, s = math.cos(yaw), math.sin(yaw)
    return _obj("mrpt::poses::CPose3D", 3, struct.pack("<12d", 0, 0, 0, c, -s, 0, s, c, 0, 0, 0, 1))


def _string(s: str) -> bytes:
    raw = s.encode("utf-8")
    return struct.pack("<I", len(raw)) + raw


def movement2d(delta: np.ndarray, t: float) -> bytes:
    """CActionRobotMovement2D v7: an odometry increment (estimationMethod emOdometry), drawn
    by MRPT's Gaussian motion model."""
    body = struct.pack("<I", 0) + _pose2d(delta) + struct.pack("<I", 0)  # emOdometry, mmGaussian
    body += struct.pack("<6f", *GAUSSIAN_MODEL)
    body += struct.pack("<I6f", *_THRUN)
    body += b"\x00" + b"\x00"  # hasVelocities, hasEncodersInfo: false
    return _obj("mrpt::obs::CActionRobotMovement2D", 7, body + struct.pack("<Q", ticks(t)))


def range_scan(ranges: np.ndarray, valid: np.ndarray, t: float, aperture: float,
               max_range: float, yaw: float) -> bytes:  # fmt: skip
    """CObservation2DRangeScan v7: beams counter-clockwise over `aperture` (MRPT puts beam i
    at -aperture / 2 + i * aperture / (B - 1) in the sensor's frame), the sensor at the
    robot's origin turned by `yaw` (the middle of the scan, relative to the heading)."""
    n = ranges.shape[0]
    body = struct.pack("<f?f", aperture, True, max_range) + _pose3d_yaw(yaw)
    body += struct.pack("<I", n) + ranges.astype("<f4").tobytes()
    body += valid.astype(np.int8).tobytes()
    body += struct.pack("<fQf", 0.01, ticks(t), 0.0)  # stdError, timestamp, beamAperture
    body += _string("LASER") + struct.pack("<d?", 0.0, False)  # deltaPitch (double), no intensity
    return _obj("mrpt::obs::CObservation2DRangeScan", 7, body)


def pair(delta: np.ndarray, ranges: np.ndarray, valid: np.ndarray, t: float, aperture: float,
         max_range: float, yaw: float) -> bytes:  # fmt: skip
    """One rawlog entry pair: CActionCollection{movement}, CSensoryFrame{scan}."""
    actions = _obj("mrpt::obs::CActionCollection", 0, struct.pack("<I", 1) + movement2d(delta, t))
    scan = range_scan(ranges, valid, t, aperture, max_range, yaw)
    frame = _obj("mrpt::obs::CSensoryFrame", 2, struct.pack("<I", 1) + scan)
    return actions + frame


def write_rawlog(path: Path | BinaryIO, t: np.ndarray, pose_odom: np.ndarray, ranges: np.ndarray,
                 angle_min: float, angle_increment: float, range_max: float) -> int:  # fmt: skip
    """Write a log (t (N,) [s], pose_odom (N, 3), ranges (N, B) [m], beams at angle_min +
    k * angle_increment) as an action / sensory-frame rawlog; the number of pairs. The beams
    keep their exact angles: aperture (B - 1) * angle_increment, the sensor turned so that
    its first beam is at angle_min. A reading at or past range_max is written as invalid."""
    n, b = ranges.shape
    aperture = float(angle_increment) * (b - 1)
    yaw = float(angle_min) + aperture / 2
    own = isinstance(path, str | Path)
    fh = open(path, "wb") if own else path  # noqa: SIM115 (closed below when opened here)
    try:
        prev = np.asarray(pose_odom[0], dtype=float)
        for k in range(n):
            cur = np.asarray(pose_odom[k], dtype=float)
            delta = compose(inverse(prev), cur)
            r = np.asarray(ranges[k], dtype=float)
            valid = np.isfinite(r) & (r > 0) & (r < range_max)
            r = np.where(valid, r, range_max)
            fh.write(pair(delta, r, valid, float(t[k]), aperture, range_max, yaw))
            prev = cur
    finally:
        if own:
            fh.close()
    return n
