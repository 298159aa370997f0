"""Parsers of single CARMEN log lines (FLASER, RAWLASER1, ROBOTLASER1, ODOM, TRUEPOS).

Field layouts (CARMEN logger, `carmen_logwrite_*`; every message ends `ipc_timestamp
ipc_hostname logger_timestamp`, older files stop at the timestamp; the ipc timestamp is read):
  FLASER num_readings [ranges] x y theta odom_x odom_y odom_theta ts ...
      (RLASER, the rear laser, has the same layout and is not read)
  RAWLASER1 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
      remission_mode num_readings [ranges] num_remissions [remissions] ts ...
      (no pose: the reader takes it from the ODOM lines at the scan's time)
  ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
      remission_mode num_readings [ranges] num_remissions [remissions] laser_x laser_y
      laser_theta robot_x robot_y robot_theta tv rv forward_safety_dist side_safety_dist
      turn_axis ts ...
  ODOM x y theta tv rv accel ts ...
  TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta ts ...
Beam i of a RAWLASER / ROBOTLASER line points at start_angle + i * angular_resolution (the
field of view is implied by the two and not needed). FLASER lines carry no geometry: their
beams spread evenly over 180 degrees from -90 degrees (181 or 361 beams include both ends;
180 or 360 step 180/n degrees, as GMapping reads them), and the log's largest reading is taken
as the sensor's maximum (`no return`: 81.91 m for a SICK LMS in cm mode, 50 m in ACES).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worker.errors import InputError
from worker.sim.laser import LaserSpec


@dataclass(frozen=True, eq=False)
class Scan:
    """One laser line: t [s], ranges (B,) [m], pose (3,) [x, y, theta] (None for RAWLASER),
    spec (None for FLASER: filled in by the reader), laser_offset (3,) laser in robot frame."""

    t: float
    ranges: np.ndarray
    pose: np.ndarray | None
    spec: LaserSpec | None
    laser_offset: np.ndarray | None = None


def floats(tokens: list[str], path: str, lineno: int) -> np.ndarray:
    """The tokens as finite float64 numbers, or an InputError naming the first bad one."""
    try:
        values = np.array(tokens, dtype=np.float64)
    except ValueError:
        bad = next(tok for tok in tokens if not _is_number(tok))
        raise InputError(f"expected a number, got {bad!r}", path=path, line=lineno) from None
    if not np.all(np.isfinite(values)):
        raise InputError("non-finite number", path=path, line=lineno)
    return values


def _is_number(tok: str) -> bool:
    try:
        float(tok)
    except ValueError:
        return False
    return True


def _count(tok: str, what: str, path: str, lineno: int) -> int:
    try:
        n = int(tok)
    except ValueError:
        raise InputError(
            f"{what} must be an integer, got {tok!r}", path=path, line=lineno
        ) from None
    if n < 0:
        raise InputError(f"{what} must be >= 0, got {n}", path=path, line=lineno)
    return n


def need(tokens: list[str], n: int, kind: str, path: str, lineno: int) -> None:
    """An InputError unless the line has at least n fields."""
    if len(tokens) < n:
        raise InputError(
            f"{kind} line has {len(tokens)} fields, needs at least {n}", path=path, line=lineno
        )


def _geometry(tok: list[str], kind: str, path: str, lineno: int) -> tuple[LaserSpec, int, int]:
    """(spec, n readings, index after the remissions) of a RAWLASER / ROBOTLASER line."""
    need(tok, 9, kind, path, lineno)
    n = _count(tok[8], "num_readings", path, lineno)
    need(tok, 10 + n, kind, path, lineno)
    n_rem = _count(tok[9 + n], "num_remissions", path, lineno)
    head = floats(tok[2:6], path, lineno)  # start_angle fov resolution max_range
    if n == 0 or head[3] <= 0.0:
        raise InputError(f"{kind} needs readings and a maximum_range > 0", path=path, line=lineno)
    if n > 1 and head[2] == 0.0:
        raise InputError(f"{kind} needs an angular_resolution != 0", path=path, line=lineno)
    return LaserSpec(n, float(head[0]), float(head[2]), float(head[3])), n, 10 + n + n_rem


def parse_rawlaser(tok: list[str], path: str, lineno: int) -> Scan:
    """A RAWLASER1 line (no pose)."""
    spec, n, k = _geometry(tok, "RAWLASER1", path, lineno)
    need(tok, k + 1, "RAWLASER1", path, lineno)
    ranges = floats(tok[9 : 9 + n], path, lineno)
    t = floats(tok[k : k + 1], path, lineno)
    return Scan(float(t[0]), ranges, None, spec)


def parse_robotlaser(tok: list[str], path: str, lineno: int) -> Scan:
    """A ROBOTLASER1 line: the robot pose is the scan's odometry pose; the laser pose gives
    the laser's offset on the robot."""
    spec, n, k = _geometry(tok, "ROBOTLASER1", path, lineno)
    need(tok, k + 12, "ROBOTLASER1", path, lineno)
    ranges = floats(tok[9 : 9 + n], path, lineno)
    rest = floats(tok[k : k + 12], path, lineno)  # laser pose, robot pose, 5 more, timestamp
    laser, robot = rest[0:3], rest[3:6]
    c, s = math.cos(robot[2]), math.sin(robot[2])
    dx, dy = laser[0] - robot[0], laser[1] - robot[1]
    dth = (laser[2] - robot[2] + math.pi) % (2.0 * math.pi) - math.pi
    offset = np.array([c * dx + s * dy, -s * dx + c * dy, dth])
    return Scan(float(rest[11]), ranges, robot, spec, offset)


def parse_flaser(tok: list[str], path: str, lineno: int) -> Scan | None:
    """A FLASER line (None for a pose-only line with 0 readings, as the thesis wrote its
    estimates). The pose is the odom_* fields (equal to x y theta in corrected logs)."""
    need(tok, 2, "FLASER", path, lineno)
    n = _count(tok[1], "num_readings", path, lineno)
    need(tok, 2 + n + 7, "FLASER", path, lineno)
    if n == 0:
        return None
    ranges = floats(tok[2 : 2 + n], path, lineno)
    rest = floats(tok[2 + n : 2 + n + 7], path, lineno)  # x y theta odom_x odom_y odom_theta t
    return Scan(float(rest[6]), ranges, rest[3:6], None)


def flaser_spec(n_beams: int, range_max: float) -> LaserSpec:
    """The geometry GMapping gives an n-beam FLASER scan (see the module docstring)."""
    inc = math.pi / (n_beams - 1) if n_beams % 2 == 1 and n_beams > 1 else math.pi / n_beams
    return LaserSpec(n_beams, -math.pi / 2.0, inc, range_max)


def parse_pose_line(tok: list[str], kind: str, path: str, lineno: int) -> tuple[float, np.ndarray]:
    """(t, (3,) pose) of an ODOM or TRUEPOS line."""
    need(tok, 8, kind, path, lineno)
    v = floats(tok[1:8], path, lineno)
    return float(v[6]), v[0:3]


def interpolate_poses(t_at: np.ndarray, t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(M, 3) poses at times t_at, linear between the (sorted) samples (t (K,), poses (K, 3)),
    the heading unwrapped first; clamped at the ends."""
    theta = np.unwrap(poses[:, 2])
    columns = (poses[:, 0], poses[:, 1], theta)
    out = np.column_stack([np.interp(t_at, t, c) for c in columns])
    out[:, 2] = (out[:, 2] + math.pi) % (2.0 * math.pi) - math.pi
    return out
