"""Standalone driving for data sets and tests: a reactive wanderer and a waypoint follower."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from worker.errors import InputError
from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.sim.laser import LaserSpec


@dataclass(frozen=True)
class WanderParams:
    """Reactive wandering on the laser scan (in the spirit of Stage's `wander` controller)."""

    v_max: float = 0.6  # [m/s] cruising speed
    w_max: float = 1.0  # [rad/s] turn rate limit
    half_width: float = 0.2  # [m] half the robot's footprint
    margin: float = 0.25  # [m] extra lateral room kept free in front of the robot
    stop_dist: float = 0.7  # [m] free distance ahead below which the robot turns in place
    slow_dist: float = 2.0  # [m] free distance ahead below which it slows down
    side_dist: float = 0.8  # [m] obstacles nearer than this at the sides push the robot away
    k_side: float = 1.5  # [rad/s per m] gain of that push
    wander_sigma: float = 0.3  # [rad/s] std of the random turn-rate component
    wander_tau: float = 3.0  # [s] its correlation time (Ornstein-Uhlenbeck)


class Wanderer:
    """Drives forward, slows near obstacles, keeps off the walls at its sides, turns on the spot
    towards the most open direction when blocked, and meanders at random in open space.
    Deterministic for its Generator."""

    def __init__(
        self, laser: LaserSpec, rng: np.random.Generator, params: WanderParams | None = None
    ):
        self.p = params or WanderParams()
        self.rng = rng
        angles = laser.angles
        self._cos = np.cos(angles)
        self._sin = np.sin(angles)
        self._left = (angles > math.radians(15)) & (angles < math.radians(110))
        self._right = (angles < -math.radians(15)) & (angles > -math.radians(110))
        self._bias = 0.0  # [rad/s] the random turn-rate component
        self._turn_dir = 0.0  # +1 left, -1 right, 0 not turning in place
        self._turn_left_s = 0.0  # [s] time left in the current turn
        self._cand = angles[::10]  # candidate headings when blocked (every 5 degrees)
        self._cand_cos = np.cos(self._cand)
        self._cand_sin = np.sin(self._cand)
        self._range_max = laser.range_max

    def command(self, ranges_m: np.ndarray, dt: float) -> tuple[float, float]:
        """(v [m/s], w [rad/s]) from the current scan `(B,)` [m]."""
        p = self.p
        xs = ranges_m * self._cos
        ys = ranges_m * self._sin
        ahead = (xs > 0.0) & (np.abs(ys) < p.half_width + p.margin)
        front = float(xs[ahead].min()) if ahead.any() else float(ranges_m.max())
        # Ornstein-Uhlenbeck turn-rate bias: smooth random meandering.
        a = math.exp(-dt / p.wander_tau)
        self._bias = a * self._bias + p.wander_sigma * math.sqrt(1 - a * a) * float(
            self.rng.standard_normal()
        )
        if self._turn_dir != 0.0:
            self._turn_left_s -= dt
            if self._turn_left_s > 0.0:
                return 0.0, self._turn_dir * p.w_max
            self._turn_dir = 0.0
        if front < p.stop_dist:
            # Blocked: turn on the spot towards the most open visible direction, or turn
            # around to look behind (the laser's blind sector) when nothing visible is open.
            phi, clear = self._most_open(xs, ys)
            if clear < p.stop_dist + 0.3:
                phi = math.copysign(math.pi, phi)
            self._turn_dir = 1.0 if phi >= 0.0 else -1.0
            self._turn_left_s = abs(phi) / p.w_max + 0.2 * float(self.rng.uniform())
            return 0.0, self._turn_dir * p.w_max
        scale = min(1.0, max(0.25, (front - p.stop_dist) / (p.slow_dist - p.stop_dist)))
        left_min = float(np.abs(ys[self._left]).min()) if self._left.any() else p.side_dist
        right_min = float(np.abs(ys[self._right]).min()) if self._right.any() else p.side_dist
        push = p.k_side * (max(0.0, p.side_dist - right_min) - max(0.0, p.side_dist - left_min))
        w = min(p.w_max, max(-p.w_max, push + self._bias))
        return p.v_max * scale, w

    def _most_open(self, xs: np.ndarray, ys: np.ndarray) -> tuple[float, float]:
        """The candidate heading (every 5 degrees of the field of view, relative [rad]) with
        the longest free lane of the robot's width, and that lane's length [m]."""
        p = self.p
        c = self._cand_cos[:, None]
        s = self._cand_sin[:, None]
        along = xs[None, :] * c + ys[None, :] * s
        lateral = np.abs(ys[None, :] * c - xs[None, :] * s)
        blocking = (along > 0.0) & (lateral < p.half_width + p.margin)
        lane = np.where(blocking, along, np.inf).min(axis=1)
        lane = np.minimum(lane, self._range_max)
        best = int(np.argmax(lane))
        return float(self._cand[best]), float(lane[best])


@dataclass(frozen=True)
class FollowParams:
    """Waypoint following on the true pose."""

    v_max: float = 0.6  # [m/s]
    w_max: float = 1.0  # [rad/s]
    k_heading: float = 1.5  # [rad/s per rad] turn-rate gain on the heading error
    turn_in_place: float = 0.6  # [rad] heading error above which the robot turns on the spot
    tolerance: float = 0.2  # [m] a waypoint is reached within this distance


class WaypointFollower:
    """Visits waypoints `(K, 2)` [x, y] in order, steering on the true pose."""

    def __init__(self, waypoints: np.ndarray, params: FollowParams | None = None):
        self.p = params or FollowParams()
        self.waypoints = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2)
        self.index = 0

    @property
    def finished(self) -> bool:
        """All waypoints reached."""
        return self.index >= len(self.waypoints)

    def command(self, pose_gt: np.ndarray) -> tuple[float, float]:
        """(v [m/s], w [rad/s]) towards the current waypoint from the true pose `(3,)`."""
        p = self.p
        while not self.finished:
            gx, gy = self.waypoints[self.index]
            dist = math.hypot(gx - pose_gt[0], gy - pose_gt[1])
            if dist > p.tolerance:
                break
            self.index += 1
        if self.finished:
            return 0.0, 0.0
        err = wrap_angle(math.atan2(gy - pose_gt[1], gx - pose_gt[0]) - pose_gt[2])
        w = min(p.w_max, max(-p.w_max, p.k_heading * err))
        if abs(err) > p.turn_in_place:
            return 0.0, w
        # Slow down on the last approach and while the heading is still off.
        v = min(p.v_max, 0.8 * dist + 0.1) * math.cos(err)
        return v, w


def read_waypoints(path: str | Path) -> np.ndarray:
    """Waypoints `(K, 2)` [x, y] from a text file: `x y` per line, `#` comments, blank lines."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("no such file", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read: {exc}", path=path) from None
    points = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.replace(",", " ").split()
        if len(fields) != 2:
            raise InputError(f"expected `x y`, got {line!r}", path=path, line=lineno)
        try:
            x, y = float(fields[0]), float(fields[1])
        except ValueError:
            raise InputError(
                f"expected two numbers, got {line!r}", path=path, line=lineno
            ) from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise InputError("waypoint must be finite", path=path, line=lineno)
        points.append((x, y))
    if not points:
        raise InputError("no waypoints in the file", path=path)
    return np.asarray(points, dtype=np.float64)
