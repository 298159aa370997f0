"""Trajectory and relations files: CARMEN logs (FLASER, ROBOTLASER1, ODOM, TRUEPOS), TUM,
and Kuemmerle relations `t1 t2 x y z roll pitch yaw`."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Literal

import numpy as np

from worker.errors import InputError
from worker.evaluate.clock import clock_order, warn_notes
from worker.evaluate.relations import Relations
from worker.evaluate.textio import (
    drop_truncated_tail,
    is_row,
    load_table,
    parse_columns,
    parse_table,
    read_text,
    write_rows,
)
from worker.evaluate.trajectory import Trajectory

TrajFormat = Literal["auto", "carmen", "tum"]
CarmenMessage = Literal["auto", "FLASER", "ROBOTLASER1", "TRUEPOS", "ODOM"]
# "auto" takes the first of these the log contains: the thesis's listener writes FLASER.
CARMEN_MESSAGES: tuple[str, ...] = ("FLASER", "ROBOTLASER1", "TRUEPOS", "ODOM")


def _count(token: str) -> int:
    n = int(token)
    if n < 0:
        raise ValueError(f"negative count {n}")
    return n


def _carmen_layout(tag: str, tokens: list[str]) -> tuple[list[int], list[int]]:
    """Column indices ([x, y, theta, t], [count columns]) of one CARMEN message line.

    Layouts (CARMEN logger header; real logs append `ipc_hostname logger_timestamp` after
    the timestamp, the thesis's files end at the timestamp):
      FLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp   (pose: the odom_* fields,
          which the thesis's listener filled with the SLAM estimate, as metricEvaluator reads)
      ROBOTLASER1 type start fov res maxrange acc remmode n r1..rn m e1..em laser_x laser_y
          laser_theta robot_x robot_y robot_theta tv rv fwd_safety side_safety turn_axis timestamp
      ODOM x y theta tv rv accel timestamp
      TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta timestamp
    Raises ValueError / IndexError on a line too short or with a bad count.
    """
    if tag == "FLASER":
        n = _count(tokens[1])
        base = 2 + n + 3
        cols, counts = [base, base + 1, base + 2, base + 3], [1]
    elif tag == "ROBOTLASER1":
        n = _count(tokens[8])
        m = _count(tokens[9 + n])
        base = 10 + n + m + 3
        cols, counts = [base, base + 1, base + 2, base + 3 + 5], [8, 9 + n]
    else:  # ODOM, TRUEPOS
        cols, counts = [1, 2, 3, 7], []
    if len(tokens) <= cols[-1]:
        raise IndexError("line too short")
    return cols, counts


def _carmen_slow(tag: str, lines: list[str], linenos: list[int], path: Path) -> np.ndarray:
    """Line-by-line CARMEN parse `(K, 4) [x, y, theta, t]`, naming the first bad line."""
    out = np.empty((len(lines), 4))
    for k, line in enumerate(lines):
        tokens = line.split()
        try:
            cols, _ = _carmen_layout(tag, tokens)
            vals = [float(tokens[c]) for c in cols]
        except (ValueError, IndexError):
            raise InputError(
                f"malformed {tag} line ({len(tokens)} fields)", path=path, line=linenos[k]
            ) from None
        if not np.isfinite(vals).all():
            raise InputError(f"non-finite value in {tag} line", path=path, line=linenos[k])
        out[k] = vals
    return out


def _pick_message(text: str, message: CarmenMessage, path: Path) -> str:
    if message != "auto":
        return message
    padded = "\n" + text
    for tag in CARMEN_MESSAGES:
        if f"\n{tag} " in padded or f"\n{tag}\t" in padded:
            return tag
    raise InputError(f"no pose messages found (looked for {', '.join(CARMEN_MESSAGES)})", path=path)


def _carmen_line_ok(line: str) -> bool:
    """True unless the line is a known pose message that cannot be read."""
    tokens = line.split()
    if not tokens or tokens[0] not in CARMEN_MESSAGES:
        return True
    try:
        cols, _ = _carmen_layout(tokens[0], tokens)
        return bool(np.isfinite([float(tokens[c]) for c in cols]).all())
    except (ValueError, IndexError):
        return False


def _carmen_tail_ok(text: str):
    """The test of a last line without its newline: readable, and not shorter than the line
    of the same message before it (a cut can leave a line that still parses)."""

    def ok(line: str) -> bool:
        if not _carmen_line_ok(line):
            return False
        tokens = line.split()
        if not tokens:
            return True
        prev = text.rfind(f"\n{tokens[0]} ", 0, len(text) - len(line))
        if prev < 0:
            return True
        end = text.find("\n", prev + 1)
        return len(text[prev + 1 : end].split()) <= len(tokens)

    return ok


def _read_carmen(text: str, message: CarmenMessage, path: Path) -> Trajectory:
    text = drop_truncated_tail(text, _carmen_tail_ok(text), path)
    tag = _pick_message(text, message, path)
    lines, linenos = [], []
    for i, line in enumerate(text.splitlines(), 1):
        if line.startswith(tag) and line[len(tag) : len(tag) + 1] in (" ", "\t"):
            lines.append(line)
            linenos.append(i)
    if not lines:
        raise InputError(f"no {tag} messages found", path=path)
    # Fast path: every line shaped like the first (same beam counts): numpy parses the
    # needed columns in bulk; any surprise falls back to the line-by-line parse.
    table = None
    try:
        cols, counts = _carmen_layout(tag, lines[0].split())
    except (ValueError, IndexError):
        counts = None
    if counts is not None:
        first = lines[0].split()
        parsed = parse_columns(lines, counts + cols)
        if parsed is not None and np.isfinite(parsed).all():
            expect = np.array([float(first[c]) for c in counts])
            if (parsed[:, : len(counts)] == expect).all():
                table = parsed[:, len(counts) :]
    if table is None:
        table = _carmen_slow(tag, lines, linenos, path)
    return _ordered(table[:, 3], table[:, :3], path)


def _ordered(t: np.ndarray, poses: np.ndarray, path: Path) -> Trajectory:
    """The trajectory of samples in the order of `worker.evaluate.clock` (warning once per
    repair), so a log's ground truth gets the times `read_laser_log` gives its scans."""
    order = clock_order(t, poses)
    warn_notes(order.notes("poses"), str(path))
    return Trajectory.from_samples(order.t, poses[order.index], path=path)


def _read_tum(text: str, path: Path) -> Trajectory:
    text = drop_truncated_tail(text, lambda line: is_row(line, 8), path)
    table = parse_table(text, 8, "t x y z qx qy qz qw", path)
    qx, qy, qz, qw = table[:, 4], table[:, 5], table[:, 6], table[:, 7]
    norm2 = qx * qx + qy * qy + qz * qz + qw * qw
    if (norm2 < 1e-12).any():
        k = int(np.argmax(norm2 < 1e-12))
        raise InputError(f"zero quaternion in pose {k + 1} (t={table[k, 0]!r})", path=path)
    # yaw of a possibly unnormalised quaternion: both atan2 arguments scale with |q|^2
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
    poses = np.column_stack([table[:, 1], table[:, 2], yaw])
    return _ordered(table[:, 0], poses, path)


def _detect_format(text: str) -> Literal["carmen", "tum"]:
    for line in io.StringIO(text):  # lazily: only the first data line matters
        body = line.split("#", 1)[0].split()
        if body:
            try:
                float(body[0])
            except ValueError:
                return "carmen"
            return "tum"
    return "tum"


def read_trajectory(
    path: str | Path, fmt: TrajFormat = "auto", message: CarmenMessage = "auto"
) -> Trajectory:
    """Read a trajectory (`.gz` transparently).

    fmt "auto" reads a CARMEN log when the first data line starts with a message name, else
    TUM. For CARMEN, `message` chooses FLASER / ROBOTLASER1 / TRUEPOS / ODOM ("auto": the
    first present in that order); other messages and `#` lines are skipped. The samples are
    ordered by `worker.evaluate.clock` (sorted, exact duplicates dropped, a degenerate clock
    replaced by the index clock, each with a warning); of the samples left sharing a
    timestamp the last is kept (`Trajectory.from_samples`). A truncated last line (no
    newline, cannot be read) is skipped with a warning.
    """
    p = Path(path)
    text = read_text(p)
    kind = _detect_format(text) if fmt == "auto" else fmt
    traj = _read_carmen(text, message, p) if kind == "carmen" else _read_tum(text, p)
    if len(traj) == 0:
        raise InputError("no poses in trajectory file", path=p)
    return traj


def write_carmen(path: str | Path, traj: Trajectory) -> None:
    """CARMEN log as the thesis's listener wrote it: `FLASER 0 0.0 0.0 0.0 x y theta t`."""
    write_rows(
        path,
        "FLASER 0 0.0 0.0 0.0 %.9f %.9f %.9f %.6f\n",
        [traj.poses[:, 0], traj.poses[:, 1], traj.poses[:, 2], traj.t],
    )


def write_tum(path: str | Path, traj: Trajectory) -> None:
    """TUM `t x y z qx qy qz qw` with z = 0 and the yaw as a rotation about z."""
    half = 0.5 * traj.poses[:, 2]
    write_rows(
        path,
        "%.6f %.9f %.9f 0 0 0 %.12f %.12f\n",
        [traj.t, traj.poses[:, 0], traj.poses[:, 1], np.sin(half), np.cos(half)],
        head="# t x y z qx qy qz qw\n",
    )


def read_relations(path: str | Path) -> Relations:
    """Kuemmerle relations `t1 t2 x y z roll pitch yaw` [s, s, m, m, m, rad, rad, rad];
    z, roll and pitch are read and ignored (2D)."""
    p = Path(path)
    table = load_table(p, 8, "t1 t2 x y z roll pitch yaw")
    return Relations(table[:, 0], table[:, 1], table[:, [2, 3, 7]])


def write_relations(path: str | Path, rel: Relations) -> None:
    """Relations file, one `t1 t2 x y 0 0 0 yaw` line per relation."""
    d = rel.delta
    write_rows(
        path,
        "%.6f %.6f %.9f %.9f 0.0 0.0 0.0 %.9f\n",
        [rel.t1, rel.t2, d[:, 0], d[:, 1], d[:, 2]],
    )


def write_errors(path: str | Path, t1: np.ndarray, t2: np.ndarray, error: np.ndarray) -> None:
    """Per-relation error file, `t1 t2 error` per line (metricEvaluator's T.errors/R.errors)."""
    write_rows(path, "%.6f %.6f %.9f\n", [t1, t2, error])
