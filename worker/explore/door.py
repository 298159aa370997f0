"""Door passage: line up with a tight passage on the path, then drive straight through it.

A square robot in a door it entered at an angle can neither turn (its diagonal is 1.41 times
its side) nor go on; with a noisy laser the marks at the jambs leave a 0.85 m door 0.5 m
wide, so the robot (0.44 m with its padding) has to arrive on the door's axis, facing along
it. The DWA's constant-curvature arcs cannot make that S-bend. This controller does, as a
robot's door-passing behaviour does: it steers onto the passage's axis (turning on the spot
where the heading is far off), faces along it, and drives through at door_speed, every motion
checked with the exact footprint against the SLAM map's obstacles around the robot (not the
latest scan's marks); when no motion is legal it hands back to the DWA and the recoveries.

Off by default (`explore.door_align`). Only a door in a wall counts: a gap whose two sides
both belong to obstacle regions at least door_wall_min long (`_in_a_wall`); every gap
between furniture stays the DWA's, since the map alone (the passage's judge) may not hold a
thin chair leg the laser sees. A passage the robot gets no farther into for door_patience is
given up for the run (`refused`), and a door is taken only where the DWA's local costmap
shows it narrower than door_engage_width. Before those rules the passage collided and stuck
among furniture on the oracle proof. It stays off because its commands bypass the safety
controller and line the robot up with the plan's chord through the door rather than the
door's own axis: under rbpf at 0.1 m noise it drove a corner into a jamb of a door the plan
crossed diagonally (README, "Laser noise").
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.params import ExploreParams

_LINE_GAIN = 3.0  # [rad/m] heading towards the axis per metre off it (clamped)
_LINE_MAX = 0.6  # [rad] before the passage
_LINE_MAX_INSIDE = 0.1  # [rad] in it
_STEER_GAIN = 2.0  # [1/s] turn rate per radian of heading error while driving
_CHECK_TIME = 0.5  # [s] each motion is checked this far ahead


class DoorPass:
    """Drives the robot through the first tight passage on its path (see the module)."""

    def __init__(self, params: ExploreParams):
        self.params = params
        self.door: tuple[np.ndarray, np.ndarray] | None = None  # (entry, exit) [m]
        self._rotating = False
        self._local: LocalCostmap | None = None  # the map's obstacles around the robot
        self.n_passages = 0  # passages driven through to their far end
        self._best_along = -math.inf  # [m] the farthest the robot got into the passage
        self._stalled = 0  # control periods since it last got 0.05 m farther
        self.refused: list[np.ndarray] = []  # entries of passages given up (door_patience)

    def reset(self) -> None:
        self.door = None
        self._rotating = False
        self._best_along = -math.inf
        self._stalled = 0

    def command(
        self,
        pose: np.ndarray,
        path_xy: np.ndarray | None,
        costmap: GlobalCostmap,
        seen: LocalCostmap | None = None,
    ) -> tuple[float, float, str] | None:
        """(v, w, kind) with kind "door_turn", "door" or "door_back", or None (no passage
        ahead, or nothing legal: the DWA decides). Passages and motions are judged on the
        SLAM map's obstacles alone (`GlobalCostmap.map_lethal`): one scan of a noisy laser
        marks a door's jambs up to two sigmas into the opening along its oblique beams, the
        map holds where many scans agree. `seen`, the DWA's local costmap (the map and the
        laser's marks): a door takes over only where it is narrower there than
        door_engage_width (None: every door)."""
        p = self.params
        if path_xy is None or len(path_xy) < 3 or costmap.map_lethal.shape != costmap.shape:
            self.reset()
            return None
        pts, along = _ahead(path_xy, float(pose[0]), float(pose[1]), p)
        seen_tight = None
        if seen is not None:
            # what the DWA sees holds the map's obstacles and more: where nothing ahead is
            # tight there, no door of the map can be taken up (the map-only window is not
            # built, which is most control periods)
            seen_tight = _narrow(pts, seen, p.door_engage_width)
            if self.door is None and not seen_tight.any():
                return None
        if self._local is None or self._local.resolution != costmap.resolution:
            self._local = LocalCostmap(p, costmap.resolution)
        local = self._local
        local.build(float(pose[0]), float(pose[1]), costmap, float(pose[2]), map_only=True)
        found = find_passage(pts, along, local, p)
        if found is not None and any(
            np.hypot(*(found[0] - e)) <= p.door_width for e in self.refused
        ):
            found = None  # given up before: the DWA and the recoveries have it
            if self.door is not None:
                self.reset()
        if found is not None and (
            self.door is None or np.hypot(*(found[0] - self.door[0])) > p.door_width
        ):
            self.reset()
            i1, k = found[2], found[3]
            if seen_tight is None or seen_tight[i1 : k + 1].any():
                self.door = found[0], found[1]
        if self.door is None:
            return None
        entry, exit_ = self.door
        axis = exit_ - entry
        length = float(np.hypot(*axis))
        u = axis / length if length > 1e-6 else _direction_at(path_xy, entry)
        rel = np.asarray(pose[:2], dtype=float) - entry
        along = float(u @ rel)
        if along > self._best_along + 0.05:
            self._best_along, self._stalled = along, 0
        else:
            self._stalled += 1
        if self._stalled > p.door_patience * p.controller_frequency:
            # lining up and backing for room got the robot no farther in: something the
            # map does not hold is in the way, or the passage is too tight to line up in
            self.refused.append(entry.copy())
            self.reset()
            return None
        off = float(u[0] * rel[1] - u[1] * rel[0])  # > 0: left of the axis
        if along > length + 0.1:
            self.n_passages += 1
            self.reset()
            return None
        if along < -(p.door_lookahead + 0.5) or abs(off) > p.door_width:
            self.reset()  # the robot left the passage's approach (a replan, a recovery)
            return None
        inside = along > -0.05
        limit = _LINE_MAX_INSIDE if inside else _LINE_MAX
        desired = math.atan2(u[1], u[0]) - max(-limit, min(limit, _LINE_GAIN * off))
        err = wrap_angle(desired - float(pose[2]))
        threshold = 0.5 * p.door_angle if self._rotating else p.door_angle
        if abs(err) > threshold:
            w_mag = max(p.min_in_place_vel_theta, min(p.max_vel_theta, 2.0 * abs(err)))
            w = math.copysign(w_mag, err)
            if _legal(pose, 0.0, w, local, p, min(_CHECK_TIME, abs(err) / w_mag + 0.1)):
                self._rotating = True
                return 0.0, w, "door_turn"
        else:
            self._rotating = False
            v = p.door_speed
            w = max(-p.max_vel_theta, min(p.max_vel_theta, _STEER_GAIN * err))
            if _legal(pose, v, w, local, p, _CHECK_TIME):
                return v, w, "door"
        # neither the turn nor the drive is legal here: back up along the axis for room
        v = p.back_out_speed_ratio * p.escape_vel
        if along < length and _legal(pose, v, 0.0, local, p, _CHECK_TIME):
            self._rotating = False
            return v, 0.0, "door_back"
        self.reset()
        return None


def _ahead(path_xy: np.ndarray, x: float, y: float, p: ExploreParams):
    """The path from its point nearest (x, y) on, door_lookahead + 2 door_width [m] of it,
    and the distance [m] along it of each point."""
    d = np.hypot(path_xy[:, 0] - x, path_xy[:, 1] - y)
    i0 = int(np.argmin(d))
    seg = np.hypot(*np.diff(path_xy[i0:], axis=0).T)
    along = np.concatenate(([0.0], np.cumsum(seg)))
    end = int(np.searchsorted(along, p.door_lookahead + 2.0 * p.door_width, side="right"))
    return np.ascontiguousarray(path_xy[i0 : i0 + end], dtype=float), along[:end]


def _narrow(pts: np.ndarray, local: LocalCostmap, width: float) -> np.ndarray:
    """`(K,) bool`: path points between obstacle cells of `local` less than `width` apart."""
    if len(pts) < 3:
        return np.zeros(len(pts), dtype=np.bool_)
    return dk.narrow_along(
        np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), local.lethal,
        float(local.origin[0]), float(local.origin[1]), local.resolution, width,
    )  # fmt: skip


def find_passage(pts: np.ndarray, along: np.ndarray, local: LocalCostmap, p: ExploreParams):
    """`(entry, exit, i1, k)` of the first door narrower than door_width on the path ahead
    (`_ahead`: `pts`, `along`) that it enters within door_lookahead (the robot possibly in
    it already), or None; i1 and k index the entry and the exit in `pts`. A path point is in
    such a passage when `local` (the map's obstacles around the robot) has obstacle cells
    on both sides of it, across the path, less than door_width apart; the passage is a door
    when both sides' obstacles belong to walls (`_in_a_wall`); the exit is a little past its
    last such point."""
    if len(pts) < 3:
        return None
    tight = _narrow(pts, local, p.door_width)
    labels = None
    i = 0
    while i < len(pts):
        if not tight[i]:
            i += 1
            continue
        i1 = i2 = i
        if along[i1] > p.door_lookahead:
            return None
        while i2 + 1 < len(pts) and tight[i2 + 1]:
            i2 += 1
        if labels is None:
            labels = _components(local.lethal)
        if _in_a_wall(pts, i1, local, labels, p):
            k = min(len(pts) - 1, int(np.searchsorted(along, along[i2] + 0.1)))
            return pts[i1].copy(), pts[k].copy(), i1, k
        i = i2 + 1
    return None


def _components(lethal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(labels, extent [cells] of each label): the 8-connected obstacle regions of `lethal`
    and the longer side of each one's bounding box."""
    labels, n = ndimage.label(lethal, structure=np.ones((3, 3), dtype=bool))
    extent = np.zeros(n + 1)
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        extent[k] = max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start)
    return labels, extent


def _in_a_wall(pts: np.ndarray, i: int, local: LocalCostmap, comps, p: ExploreParams) -> bool:
    """Whether the obstacles found on both sides of the path at pts[i], across it, are each
    part of a region at least door_wall_min long: a door in a wall, not a gap between
    pieces of furniture."""
    labels, extent = comps
    j0, j1 = max(0, i - 1), min(len(pts) - 1, i + 1)
    d = pts[j1] - pts[j0]
    norm = float(np.hypot(*d))
    if norm == 0.0:
        return False
    nx, ny = -d[1] / norm, d[0] / norm
    res = local.resolution
    h, w = labels.shape
    for sgn in (1.0, -1.0):
        label = 0
        for step in range(int(p.door_width / (0.5 * res)) + 1):
            r = sgn * step * 0.5 * res
            ix = int(math.floor((pts[i, 0] + r * nx - local.origin[0]) / res))
            iy = int(math.floor((pts[i, 1] + r * ny - local.origin[1]) / res))
            if not (0 <= ix < w and 0 <= iy < h):
                break
            if labels[iy, ix]:
                label = labels[iy, ix]
                break
        if label == 0 or extent[label] * res < p.door_wall_min:
            return False
    return True


def _direction_at(path_xy: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Unit direction of the path at its point nearest xy."""
    i = int(np.argmin(np.hypot(path_xy[:, 0] - xy[0], path_xy[:, 1] - xy[1])))
    a, b = path_xy[max(0, i - 1)], path_xy[min(len(path_xy) - 1, i + 1)]
    d = b - a
    n = float(np.hypot(*d))
    return d / n if n > 1e-9 else np.array([1.0, 0.0])


def _legal(pose, v: float, w: float, local: LocalCostmap, p: ExploreParams, duration: float):
    """Driving (v, w) for `duration` [s] keeps the exact footprint (no padding: these are
    slow, finely checked motions) clear of the local costmap's obstacles."""
    return dk.motion_legal(
        float(pose[0]), float(pose[1]), float(pose[2]), v, w, duration,
        local.lethal, local.near, local.inner, float(local.origin[0]),
        float(local.origin[1]), local.resolution, p.footprint_half_m,
        p.angular_sim_granularity,
    )  # fmt: skip
