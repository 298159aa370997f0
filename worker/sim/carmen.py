"""CARMEN log files: write ODOM / ROBOTLASER1 / TRUEPOS lines; read laser logs back.

Line layouts (CARMEN logger; every message ends `ipc_timestamp ipc_hostname logger_timestamp`):
  ODOM x y theta tv rv accel
  ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range accuracy
      remission_mode num_readings [ranges] num_remissions [remissions] laser_x laser_y
      laser_theta robot_x robot_y robot_theta tv rv forward_safety_dist side_safety_dist
      turn_axis
  FLASER num_readings [ranges] x y theta odom_x odom_y odom_theta
  TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta
"""

from __future__ import annotations

import gzip
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from worker.errors import InputError
from worker.sim.format_kernels import Fixed3Formatter
from worker.sim.laser import LaserSpec

HOSTNAME = "mapqual"
LASER_TYPE_SIMULATED = 3  # CARMEN's SIMULATED_LASER
FLASER_RANGE_MAX = 81.9  # [m] SICK LMS maximum in cm mode: classic logs mark no-return with it

HEADER = (
    "# CARMEN Logfile\n"
    "# file format is one message per line\n"
    "# message_name [message contents] ipc_timestamp ipc_hostname logger_timestamp\n"
    "# message formats defined: ODOM ROBOTLASER1 TRUEPOS\n"
    "# ODOM x y theta tv rv accel\n"
    "# ROBOTLASER1 laser_type start_angle field_of_view angular_resolution maximum_range "
    "accuracy remission_mode num_readings [range_readings] num_remissions [remission values] "
    "laser_pose_x laser_pose_y laser_pose_theta robot_pose_x robot_pose_y robot_pose_theta "
    "laser_tv laser_rv forward_safety_dist side_safety_dist turn_axis\n"
    "# TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta\n"
)


class CarmenWriter:
    """Writes one ODOM, ROBOTLASER1 and TRUEPOS line per tick to a text stream.

    The robot (and laser) pose in ROBOTLASER1 is the odometry pose, as a real robot logs it;
    TRUEPOS carries the simulator's ground truth. Fixed-precision formatting, so the same run
    gives the same bytes.
    """

    def __init__(self, stream: TextIO, laser: LaserSpec, comment: str | None = None):
        self.stream = stream
        self.laser = laser
        self._format = Fixed3Formatter()
        self._laser_head = (
            f"ROBOTLASER1 {LASER_TYPE_SIMULATED} {laser.angle_min:.12f} {laser.fov:.12f} "
            f"{laser.angle_increment:.12f} {laser.range_max:.3f} 0.010 0 {laser.n_beams} "
        )
        stream.write(HEADER)
        if comment:
            for line in comment.splitlines():
                stream.write(f"# {line}\n")

    def write_tick(
        self, t: float, pose_gt, pose_odom, v: float, w: float, ranges_m: np.ndarray
    ) -> None:
        """Log one time step: `pose_*` `(3,)` [x, y, theta], `ranges_m` `(B,)` [m]."""
        if ranges_m.shape[0] != self.laser.n_beams:
            raise ValueError(f"expected {self.laser.n_beams} ranges, got {ranges_m.shape[0]}")
        ox, oy, oth = float(pose_odom[0]), float(pose_odom[1]), float(pose_odom[2])
        tail = f"{t:.6f} {HOSTNAME} {t:.6f}\n"
        odom = f"{ox:.6f} {oy:.6f} {oth:.6f}"
        self.stream.write(f"ODOM {odom} {v:.6f} {w:.6f} 0.000000 {tail}")
        self.stream.write(self._laser_head)
        self.stream.write(self._format(ranges_m))
        self.stream.write(f" 0 {odom} {odom} {v:.6f} {w:.6f} 0.000 0.000 0.000 {tail}")
        self.stream.write(
            f"TRUEPOS {float(pose_gt[0]):.6f} {float(pose_gt[1]):.6f} {float(pose_gt[2]):.6f} "
            f"{odom} {tail}"
        )


@dataclass(frozen=True, eq=False)
class LaserLog:
    """A laser log read back: N scans with the odometry pose at each, and the ground truth.

    `t` `(N,)` [s]; `ranges` `(N, B)` float32 [m]; `pose_odom` `(N, 3)` [x, y, theta];
    `t_gt`, `pose_gt` `(M,)`, `(M, 3)` from TRUEPOS lines, or None when the log has none;
    `t_odom`, `odom` `(K,)`, `(K, 3)` from ODOM lines (empty when none).
    """

    t: np.ndarray
    ranges: np.ndarray
    pose_odom: np.ndarray
    laser: LaserSpec
    t_gt: np.ndarray | None
    pose_gt: np.ndarray | None
    t_odom: np.ndarray
    odom: np.ndarray
    source: str


def _open_text(path: Path):
    """Open a log for reading, decompressing `.gz` transparently."""
    if path.suffix == ".gz":
        return gzip.open(path, "rt", encoding="utf-8", errors="replace")
    return open(path, encoding="utf-8", errors="replace")


def _floats(tokens: list[str], path: Path, lineno: int) -> np.ndarray:
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


def _count(tok: str, what: str, path: Path, lineno: int) -> int:
    try:
        n = int(tok)
    except ValueError:
        raise InputError(
            f"{what} must be an integer, got {tok!r}", path=path, line=lineno
        ) from None
    if n < 0:
        raise InputError(f"{what} must be >= 0, got {n}", path=path, line=lineno)
    return n


def _need(tokens: list[str], n: int, kind: str, path: Path, lineno: int) -> None:
    if len(tokens) < n:
        raise InputError(
            f"{kind} line has {len(tokens)} fields, needs at least {n}", path=path, line=lineno
        )


class _Scans:
    """Accumulates scans of one message type."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.ranges: list[np.ndarray] = []
        self.pose: list[np.ndarray] = []
        self.spec: LaserSpec | None = None


def _parse_robotlaser(tok, path, lineno, acc: _Scans) -> None:
    _need(tok, 9, "ROBOTLASER1", path, lineno)
    n = _count(tok[8], "num_readings", path, lineno)
    _need(tok, 10 + n, "ROBOTLASER1", path, lineno)
    n_rem = _count(tok[9 + n], "num_remissions", path, lineno)
    k = 10 + n + n_rem
    _need(tok, k + 12, "ROBOTLASER1", path, lineno)
    head = _floats(tok[2:6], path, lineno)  # start_angle fov resolution max_range
    ranges = _floats(tok[9 : 9 + n], path, lineno)
    rest = _floats(tok[k : k + 12], path, lineno)  # laser pose, robot pose, 5 more, timestamp
    if n == 0 or head[3] <= 0.0:
        raise InputError(
            "ROBOTLASER1 needs readings and a maximum_range > 0", path=path, line=lineno
        )
    spec = LaserSpec(n, float(head[0]), float(head[2]), float(head[3]))
    _add_scan(acc, spec, float(rest[11]), ranges, rest[3:6], path, lineno)


def _parse_flaser(tok, path, lineno, acc: _Scans) -> None:
    _need(tok, 2, "FLASER", path, lineno)
    n = _count(tok[1], "num_readings", path, lineno)
    _need(tok, 2 + n + 7, "FLASER", path, lineno)
    if n == 0:
        return  # a pose-only line (as the thesis wrote estimated poses): no scan to read
    ranges = _floats(tok[2 : 2 + n], path, lineno)
    rest = _floats(tok[2 + n : 2 + n + 7], path, lineno)  # x y theta odom_x odom_y odom_theta t
    # Classic FLASER: beams spread evenly over 180 degrees from -90 degrees (181 or 361 beams
    # include both ends; 180 or 360 beams step 180/n degrees, as GMapping reads them).
    inc = math.pi / (n - 1) if n % 2 == 1 and n > 1 else math.pi / n
    spec = LaserSpec(n, -math.pi / 2.0, inc, FLASER_RANGE_MAX)
    _add_scan(acc, spec, float(rest[6]), ranges, rest[3:6], path, lineno)


def _add_scan(acc: _Scans, spec, t, ranges, pose, path, lineno) -> None:
    if acc.spec is None:
        acc.spec = spec
    elif spec.n_beams != acc.spec.n_beams:
        raise InputError(
            f"scan has {spec.n_beams} readings, earlier scans {acc.spec.n_beams}",
            path=path,
            line=lineno,
        )
    acc.t.append(t)
    acc.ranges.append(ranges)
    acc.pose.append(pose)


def read_laser_log(path: str | Path) -> LaserLog:
    """Read a CARMEN log (ROBOTLASER1, else FLASER scans; ODOM; TRUEPOS), `.gz` allowed.

    Other message types (PARAM, SYNC, RAWLASER, ...) and `#` comments are skipped. A malformed
    line of a known type raises InputError naming the file and line.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", path=path)
    robot = _Scans()
    flaser = _Scans()
    gt_t: list[float] = []
    gt_pose: list[np.ndarray] = []
    odom_t: list[float] = []
    odom_pose: list[np.ndarray] = []
    try:
        with _open_text(path) as fh:
            for lineno, line in enumerate(fh, start=1):
                tok = line.split()
                if not tok or tok[0].startswith("#"):
                    continue
                kind = tok[0]
                if kind == "ROBOTLASER1":
                    _parse_robotlaser(tok, path, lineno, robot)
                elif kind == "FLASER":
                    _parse_flaser(tok, path, lineno, flaser)
                elif kind == "ODOM":
                    _need(tok, 8, "ODOM", path, lineno)
                    v = _floats(tok[1:8], path, lineno)
                    odom_t.append(float(v[6]))
                    odom_pose.append(v[0:3])
                elif kind == "TRUEPOS":
                    _need(tok, 8, "TRUEPOS", path, lineno)
                    v = _floats(tok[1:8], path, lineno)
                    gt_t.append(float(v[6]))
                    gt_pose.append(v[0:3])
    except (OSError, EOFError, UnicodeError) as exc:
        raise InputError(f"cannot read the log: {exc}", path=path) from None
    acc = robot if robot.t else flaser
    if not acc.t:
        raise InputError("no ROBOTLASER1 or FLASER scans in this log", path=path)
    return LaserLog(
        t=np.asarray(acc.t, dtype=np.float64),
        ranges=np.asarray(acc.ranges, dtype=np.float32),
        pose_odom=np.asarray(acc.pose, dtype=np.float64).reshape(-1, 3),
        laser=acc.spec,
        t_gt=np.asarray(gt_t, dtype=np.float64) if gt_t else None,
        pose_gt=np.asarray(gt_pose, dtype=np.float64).reshape(-1, 3) if gt_t else None,
        t_odom=np.asarray(odom_t, dtype=np.float64),
        odom=np.asarray(odom_pose, dtype=np.float64).reshape(-1, 3),
        source=str(path),
    )
