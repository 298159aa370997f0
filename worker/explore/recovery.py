"""Ways out of trouble: back out along the trail, unwedge from contact, make a back-off safe."""

from __future__ import annotations

import math

import numpy as np

from worker.explore import costmap_kernels as ck
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.dwa import DwaPlanner, drive, wrap_angle
from worker.explore.params import DwaParams, RecoveryParams

_UNWEDGE_STEPS = 20  # Euler steps of an unwedging motion's end pose


class Trail:
    """The robot's recent positions `(2,)` [m] (map frame), trail_spacing apart, newest last:
    the way it came, which was free."""

    def __init__(self, params: RecoveryParams):
        self.params = params
        self.points: list[np.ndarray] = []
        # per point: the robot's heading there [rad], and whether the local planner drove
        # it there forwards (its footprint checked with footprint_padding on the way)
        self.headings: list[float] = []
        self.planned: list[bool] = []

    def grow(self, pose: np.ndarray, planned: bool = False) -> None:
        """Add the robot's pose if it moved trail_spacing; `planned`: it got there on the
        local planner's forward command."""
        p = self.params
        if not self.points or np.hypot(*(pose[:2] - self.points[-1])) >= p.trail_spacing:
            self.points.append(pose[:2].copy())
            self.headings.append(float(pose[2]))
            self.planned.append(bool(planned))
            if len(self.points) > p.trail_cap:
                del self.points[: p.trail_trim]
                del self.headings[: p.trail_trim]
                del self.planned[: p.trail_trim]

    def closed_behind(self, L: LocalCostmap, reach: float) -> np.ndarray | None:
        """The way out of a trap: when the last `reach` [m] of the trail, all of it driven
        by the local planner (which checked it with footprint_padding), now puts the bare
        footprint on an obstacle cell at a pose the robot drove through (the map drew the
        gap it came through wider than it is, from the side it came from; the robot cannot
        drive back through it), the trail point to back out to:
        footprint_half_m + reach before the first pose that fails, in a straight line from
        it (or the trail's start). None: no trap (or the stretch was not all planned)."""
        p = self.params
        n = len(self.points)
        if n < p.retrace_min_points or not self.planned[-1]:
            return None
        pts = np.asarray(self.points)
        d = np.hypot(pts[:, 0] - pts[-1, 0], pts[:, 1] - pts[-1, 1])
        within = np.flatnonzero(d <= reach)
        k0 = int(within[0]) if within.size else n - 1
        if k0 == n - 1 or not all(self.planned[k0:]):
            return None
        # the bare footprint (as for the back-out): with the padding, a wall face mapped a
        # cell nearer after the robot drove past it 2 cm off made traps in open rooms
        # (Freiburg52_scan_furnitures). The local costmap's first test, a centre within the
        # padded half side of an obstacle, is its own (`footprint_collides`' inner layer)
        half = L.params.footprint_half_m
        poses = np.column_stack((pts[k0:], self.headings[k0:]))
        hit = ck.first_colliding_pose(
            L.lethal, L.near, L.inner, float(L.origin[0]), float(L.origin[1]), L.resolution,
            poses, half,
        )  # fmt: skip
        if hit < 0:
            return None
        first = k0 + int(hit)
        return _newest_from(pts, pts[first], half + reach, end=first)

    def back_target(self, xy: np.ndarray | None = None) -> np.ndarray | None:
        """The point to back out to: walking back along the trail from its newest point, the
        first one at least retrace_points x trail_spacing (0.8 m) in a straight line from `xy`
        (the robot; default the newest point), else the trail's start; None when the trail
        is too short. Measured from the robot, not counted in points: after dithering on
        the spot the newest points all lie where it stands, and the way it came is behind
        them."""
        p = self.params
        if len(self.points) < p.retrace_min_points:
            return None
        here = self.points[-1] if xy is None else np.asarray(xy, dtype=float)[:2]
        reach = p.retrace_points * p.trail_spacing
        return _newest_from(np.asarray(self.points), here, reach - 1e-9)

    def carrot(self, xy, target: np.ndarray, lookahead: float) -> np.ndarray:
        """The point to steer the back-out at: walking back along the trail towards
        `target` (a trail point, `back_target`) from the trail point nearest the robot at
        `xy`, the first one at least `lookahead` [m] from it, else `target`. The back-out
        goes the way the robot came, bends included, not in a straight line across them:
        between table legs or through a narrow door that line cuts a corner the robot's
        way in went round."""
        k0 = self._index_of(target)
        if k0 is None:
            return np.asarray(target, dtype=float).copy()
        seg = np.asarray(self.points[k0:])
        d = np.hypot(seg[:, 0] - xy[0], seg[:, 1] - xy[1])
        near = int(np.argmin(d))
        far = np.flatnonzero(d[: near + 1] >= lookahead)
        return seg[int(far[-1]) if far.size else 0].copy()

    def unchecked(self) -> None:
        """Count the trail so far as not driven by the local planner: a trap found on it
        (`closed_behind`) is dealt with, whether or not the back-out got the robot out."""
        self.planned = [False] * len(self.planned)

    def cut_to(self, target: np.ndarray) -> None:
        """A back-out to `target` ended: forget the trail after the newest point at it (the
        stretch backed out of, and the back-out's own points), so the next back-out goes on
        further the way the robot came; the whole trail when the point was trimmed off."""
        k = self._index_of(target)
        if k is None:
            self.clear()
        else:
            del self.points[k + 1 :]
            del self.headings[k + 1 :]
            del self.planned[k + 1 :]

    def _index_of(self, target: np.ndarray) -> int | None:
        """Index of the newest trail point equal to `target`, or None (trimmed off)."""
        if not self.points:
            return None
        pts = np.asarray(self.points)
        at = np.flatnonzero((pts[:, 0] == target[0]) & (pts[:, 1] == target[1]))
        return int(at[-1]) if at.size else None

    def clear(self) -> None:
        self.points.clear()
        self.headings.clear()
        self.planned.clear()


def _newest_from(pts: np.ndarray, here, dist: float, end: int | None = None) -> np.ndarray:
    """The newest of the points `(K, 2)` before index `end` (default all) at least `dist`
    [m] from `here` in a straight line, else the oldest point (a copy)."""
    old = pts[:end]
    far = np.flatnonzero(np.hypot(old[:, 0] - here[0], old[:, 1] - here[1]) >= dist)
    return pts[int(far[-1]) if far.size else 0].copy()


def _legal(p: DwaParams, L: LocalCostmap, pose, v: float, w: float, duration: float, half):
    """Driving (v, w) for `duration` [s] from pose keeps a footprint of half side `half` clear."""
    return dk.motion_legal(
        float(pose[0]), float(pose[1]), float(pose[2]), v, w, duration, L.lethal, L.near,
        L.inner, float(L.origin[0]), float(L.origin[1]), L.resolution, half, p.sim_granularity,
    )  # fmt: skip


def back_out(
    r: RecoveryParams, p: DwaParams, L: LocalCostmap, pose: np.ndarray, d: np.ndarray
) -> tuple[float, float] | None:
    """Reverse along `d (2,)` [m] (towards the target, map frame), checked against the local
    costmap (with the bare footprint of its settings): turning the rear towards it, and
    reversing once it about points there; None when no such motion is legal. `p`: the local
    planner's limits."""
    # backwards: the robot's rear points at the target
    err = wrap_angle(math.atan2(d[1], d[0]) + math.pi - pose[2])
    w = max(-p.max_vel_theta, min(p.max_vel_theta, r.back_out_gain * err))
    v = p.escape_vel * r.back_out_speed_ratio if abs(err) < r.retrace_max_heading_error else 0.0
    for vv, ww in ((v, w), (0.0, w), (v, 0.0)):
        if (vv, ww) != (0.0, 0.0) and _legal(
            p, L, pose, vv, ww, r.back_out_check_time, L.params.footprint_half_m
        ):
            return vv, ww
    return None


def unwedge(
    r: RecoveryParams, p: DwaParams, L: LocalCostmap, costmap: GlobalCostmap, pose: np.ndarray
) -> tuple[float, float] | None:
    """Out of contact: the footprint overlaps an obstacle cell (the scan's or the map's) at
    the robot's own pose, so every motion collides, backing away included (in clutter the
    DWA's unpadded pass can end a few centimetres from furniture, and a cell is 5 cm).
    The slow motion (back, forward, turn, for unwedge_time) that takes the footprint
    farthest from the cells it touches without touching any other, backwards first on
    ties (sliding along an obstacle at its side is a way out too); None when it touches
    nothing, or every such motion would take it nearer to them."""
    x, y, th = (float(v) for v in pose)
    half = L.params.footprint_half_m
    L.build(x, y, costmap, th)
    if not ck.footprint_collides(
        L.lethal, L.near, L.inner, float(L.origin[0]), float(L.origin[1]), L.resolution,
        x, y, th, half,
    ):  # fmt: skip
        return None
    blocked = L.lethal.copy()
    L.build(x, y, costmap, th, clear_touching=True)  # same window: same origin
    iy, ix = np.nonzero(blocked & ~L.lethal)
    if iy.size == 0:
        return None
    cx = L.origin[0] + (ix + 0.5) * L.resolution
    cy = L.origin[1] + (iy + 0.5) * L.resolution
    best, best_gap = None, square_gap(cx, cy, x, y, th, half) - 1e-6
    duration = r.unwedge_time
    for v in (p.escape_vel, 0.0, p.min_vel_x):
        for w in (-p.min_in_place_vel_theta, 0.0, p.min_in_place_vel_theta):
            if (v, w) == (0.0, 0.0) or not _legal(p, L, (x, y, th), v, w, duration, half):
                continue
            ex, ey, eth = drive(x, y, th, v, w, duration, _UNWEDGE_STEPS)
            gap = square_gap(cx, cy, ex, ey, eth, half)
            if gap > best_gap:
                best, best_gap = (v, w), gap
    return best


def safe_override(
    backoff_time: float,
    L: LocalCostmap,
    dwa: DwaPlanner,
    pose: np.ndarray,
    vw: tuple[float, float],
    v0: float,
    w0: float,
    planned: tuple[float, float] = (0.0, 0.0),
) -> tuple[float, float]:
    """The safety controller backs off blind (the laser does not see behind): check the
    manoeuvre `vw` against the local costmap, which holds the map's obstacles; if it would
    hit something, only turn; if that too, let the local planner turn or back off its way;
    if it cannot either, its own (collision-checked) `planned` command, as the only way
    out of the corner. backoff_time [s]: SafetyParams.safety_backoff_time."""
    for v, w in (vw, (0.0, vw[1])):
        if _legal(dwa.params, L, pose, v, w, backoff_time, L.params.footprint_half_m):
            return v, w
    if dwa.path_xy is not None:
        cmd = dwa.command(pose, v0, w0, L, None, no_forward=True)
        if cmd.legal:
            return cmd.v, cmd.w
    return planned


def square_gap(px: np.ndarray, py: np.ndarray, x: float, y: float, th: float, half: float):
    """[m] the least distance from the points `(K,)` to the square footprint (half side
    `half`) at (x, y, th); 0 for a point inside."""
    dx, dy = px - x, py - y
    c, s = math.cos(th), math.sin(th)
    u = np.maximum(np.abs(dx * c + dy * s) - half, 0.0)
    v = np.maximum(np.abs(-dx * s + dy * c) - half, 0.0)
    return float(np.min(np.hypot(u, v)))
