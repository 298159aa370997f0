"""CARMEN log files: write ODOM / ROBOTLASER1 / TRUEPOS lines; read real laser logs back.

The line layouts are in `worker.sim.carmen_lines`. Reading follows what real logs hold
(issue 17): any mix of ROBOTLASER1, FLASER, RAWLASER1, ODOM and TRUEPOS lines, comments and
other messages skipped, the sample order of `worker.evaluate.clock`, a truncated last line
skipped with a warning.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from worker.errors import InputError
from worker.evaluate.clock import clock_order, warn_notes
from worker.evaluate.textio import read_bytes
from worker.sim.carmen_lines import (
    Scan,
    flaser_spec,
    interpolate_poses,
    parse_flaser,
    parse_pose_line,
    parse_rawlaser,
    parse_robotlaser,
)
from worker.sim.format_kernels import Fixed3Formatter
from worker.sim.laser import LaserSpec

HOSTNAME = "mapqual"
FLASER_NO_RETURN_M = 81.91  # [m] SICK LMS no-return in cm mode
SATURATED_SHARE = 0.001  # a FLASER log's largest reading held this often is its no-return
SATURATED_MIN = 10  # ... and at least this many times
LASER_TYPE_SIMULATED = 3  # CARMEN's SIMULATED_LASER

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
    `t_odom`, `odom` `(K,)`, `(K, 3)` from ODOM lines (empty when none); `message`: the scan
    lines read; `notes`: the repairs made while reading (also issued as InputWarnings).
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
    message: str = "ROBOTLASER1"
    notes: tuple[str, ...] = ()


# the scan message read when a log holds several (a ROBOTLASER1 line carries the most)
SCAN_MESSAGES: tuple[str, ...] = ("ROBOTLASER1", "FLASER", "RAWLASER1")
_SCAN_PARSERS = {
    "ROBOTLASER1": parse_robotlaser,
    "FLASER": parse_flaser,
    "RAWLASER1": parse_rawlaser,
}


class _Lines:
    """What the lines of a log hold, by message."""

    def __init__(self) -> None:
        self.scans: dict[str, list[Scan]] = {k: [] for k in SCAN_MESSAGES}
        self.beams: dict[str, int] = {}
        self.poses: dict[str, tuple[list[float], list[np.ndarray]]] = {
            "TRUEPOS": ([], []),
            "ODOM": ([], []),
        }

    def add(self, tok: list[str], path: str, lineno: int) -> None:
        kind = tok[0]
        if kind in _SCAN_PARSERS:
            scan = _SCAN_PARSERS[kind](tok, path, lineno)
            if scan is None:
                return
            n0 = self.beams.setdefault(kind, scan.ranges.shape[0])
            if scan.ranges.shape[0] != n0:
                raise InputError(
                    f"{kind} scan has {scan.ranges.shape[0]} readings, earlier ones {n0}",
                    path=path,
                    line=lineno,
                )
            self.scans[kind].append(scan)
        elif kind in self.poses:
            t, pose = parse_pose_line(tok, kind, path, lineno)
            self.poses[kind][0].append(t)
            self.poses[kind][1].append(pose)


def _read_lines(path: Path) -> tuple[_Lines, list[str]]:
    """Every line parsed; a malformed last line without its newline is reported and skipped,
    any other malformed line raises InputError with its number."""
    text = read_bytes(path).decode("utf-8", errors="replace")
    lines = text.split("\n")
    out = _Lines()
    notes: list[str] = []
    fields: dict[str, int] = {}  # fields of the latest line of each message
    for lineno, line in enumerate(lines, start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        last = lineno == len(lines)  # the last line, and it has no newline
        try:
            if last and len(tok) < fields.get(tok[0], 0):  # cut, though it may still parse
                raise InputError("shorter than the line before it", path=path, line=lineno)
            out.add(tok, str(path), lineno)
        except InputError:
            if not last:
                raise
            notes.append(f"line {lineno} is truncated ({tok[0]}, {len(tok)} fields): skipped")
        fields[tok[0]] = len(tok)
    return out, notes


def _pose_track(lines: _Lines, kind: str) -> tuple[np.ndarray, np.ndarray]:
    """(t (K,), poses (K, 3)) of the ODOM or TRUEPOS lines in the clock rule's order."""
    t = np.asarray(lines.poses[kind][0], dtype=np.float64)
    poses = np.asarray(lines.poses[kind][1], dtype=np.float64).reshape(-1, 3)
    order = clock_order(t, poses)
    return order.t, poses[order.index]


def _scan_arrays(kind: str, scans: list[Scan], lines: _Lines, path: Path):
    """(t, ranges, pose_odom, spec, notes) of the chosen scans, in the clock rule's order."""
    t = np.array([s.t for s in scans], dtype=np.float64)
    ranges = np.array([s.ranges for s in scans], dtype=np.float32)
    if kind == "RAWLASER1":
        t_odom, odom = _pose_track(lines, "ODOM")
        degenerate = clock_order(t, ranges).degenerate or clock_order(t_odom, odom).degenerate
        if t_odom.shape[0] == 0 or degenerate:
            raise InputError(
                "RAWLASER1 scans carry no pose, and no ODOM lines on a usable clock give one",
                path=path,
            )
        pose = interpolate_poses(t, t_odom, odom)
    else:
        pose = np.array([s.pose for s in scans], dtype=np.float64)
    order = clock_order(t, np.column_stack([pose, ranges]))
    spec = scans[0].spec
    if spec is None:
        spec = flaser_spec(ranges.shape[1], _flaser_range_max(ranges))
    idx = order.index
    return order.t, ranges[idx], pose[idx], spec, order.notes("scans")


def _flaser_range_max(ranges: np.ndarray) -> float:
    """[m] The maximum of a FLASER log, which does not say it: its largest reading when at
    least SATURATED_SHARE of all readings (and SATURATED_MIN) hold it (a sensor's no-return
    value: 81.91 m for a SICK LMS, 50 m in ACES); else 81.91 m, or just above the largest
    reading if that is more (so no real return is taken for a no-return)."""
    top = float(ranges.max()) if ranges.size else 0.0
    held = np.count_nonzero(ranges == ranges.max()) if ranges.size else 0
    if top > 0 and held >= max(SATURATED_SHARE * ranges.size, SATURATED_MIN):
        return float(f"{top:.6g}")  # the printed value, not its float32
    return max(FLASER_NO_RETURN_M, float(f"{top:.6g}") + 0.02)


def read_laser_log(path: str | Path) -> LaserLog:
    """Read a CARMEN log (`.gz` allowed): the scans of ROBOTLASER1, else FLASER, else
    RAWLASER1 lines (posed from ODOM); ODOM; TRUEPOS.

    Other message types (PARAM, SYNC, NEFF, RLASER, ...) and `#` comments are skipped. A
    malformed line of a known type raises InputError naming the file and line, unless it is
    the last line and has no newline (a log cut off): that one is skipped with a warning.
    Scans are ordered by `worker.evaluate.clock.clock_order` (a warning for each repair).
    """
    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", path=path)
    lines, notes = _read_lines(path)
    kind = next((k for k in SCAN_MESSAGES if lines.scans[k]), None)
    if kind is None:
        raise InputError("no ROBOTLASER1, FLASER or RAWLASER1 scans in this log", path=path)
    t, ranges, pose, spec, scan_notes = _scan_arrays(kind, lines.scans[kind], lines, path)
    notes += scan_notes
    warn_notes(notes, str(path))
    t_gt, pose_gt = _pose_track(lines, "TRUEPOS")
    t_odom, odom = _pose_track(lines, "ODOM")
    return LaserLog(
        t=t,
        ranges=ranges,
        pose_odom=pose,
        laser=spec,
        t_gt=t_gt if t_gt.shape[0] else None,
        pose_gt=pose_gt if t_gt.shape[0] else None,
        t_odom=t_odom,
        odom=odom,
        source=str(path),
        message=kind,
        notes=tuple(notes),
    )
