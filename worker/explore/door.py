"""Door passage: line up with a door on the path, on the door's own axis, then drive through.

A square robot in a door it entered at an angle can neither turn (its diagonal is 1.41 times
its side) nor go on; with a noisy laser the marks at the jambs leave a 0.85 m door 0.5 m
wide, so the robot (0.44 m with its padding) has to arrive on the door's axis, facing along
it. The DWA's constant-curvature arcs cannot make that S-bend. This controller does, as a
robot's door-passing behaviour does:

1. the door: on the path ahead, the narrowest point between the SLAM map's obstacles on its
   two sides (the nearest cells across the path, up to 60 degrees off its normal, so that a
   door the plan crosses diagonally is found too), refined to the door's own jambs: their
   midpoint is the door's centre, the normal of the line between them its axis (not the
   plan's chord through the door, which may cross a thick wall 0.6 rad off it);
2. a pre-door point on the axis, where the footprint (with door_margin) fits and can turn on
   the spot, and which the robot, when off the axis, can drive to with the map's walls out
   of the safety controller's band (safety_distance plus two sigmas of range noise ahead);
   it turns towards it and drives there, or, where no such point is (a jamb that is a deep
   wall block beside the axis), turns its back to it and reverses there;
3. it turns on the spot to face along the axis, and drives through at door_speed, steering
   back onto the axis.

Every motion is checked with the footprint grown by door_margin (for the SLAM pose's error)
against the SLAM map's obstacles around the robot (not the latest scan's marks); forward
motions are also the safety controller's to veto (`Navigator._drive`). When no motion is
legal it hands back to the DWA and the recoveries.

On with a noisy laser (`explore.doors.noisy_door_align`, `ExploreParams.for_range_noise`), off on
a noise-free one (`explore.doors.door_align`), where it makes explorations 20 % longer for no
gain (docs/results/laser-noise.md). Only a door in a wall counts: the two jambs' obstacle
regions must each be at least door_wall_min long, and the path must cross the line between
them; every gap between furniture stays the DWA's, since the map alone (the passage's judge)
may not hold a thin chair leg the laser sees. A passage the robot makes no progress in for
door_patience is given up for the goal being pursued (`refused`; the next goal may try it
again: what stalled it, a safety stop on a noisy reading, a chair, may be gone), and a door
is taken only where the DWA's local costmap shows it narrower than door_engage_width. A
robot in a door facing back along it (a new goal behind) reverses out rather than turning
round in the door.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.door_geometry import Door, crosses, find_door, gaps, path_ahead, tight_near
from worker.explore.params import CostmapParams, DoorParams, DwaParams

_LINE_GAIN = 3.0  # [rad/m] heading towards the axis per metre off it (clamped)
_LINE_MAX = 0.6  # [rad] before the passage
_LINE_MAX_INSIDE = 0.1  # [rad] in it
_STEER_GAIN = 2.0  # [1/s] turn rate per radian of heading error while driving
_CHECK_TIME = 0.5  # [s] each motion is checked this far ahead
_ON_AXIS = 0.04  # [m] this near the axis the robot lines up where it is
_OFF_AXIS = 0.1  # [m] this far off it, before the door, it goes back to the pre-door point
_AT_PRE = 0.04  # [m] the pre-door point is reached this near
_PRE_DISTANCES = (0.35, 0.5, 0.65, 0.8)  # [m] pre-door points tried, before the door's entry
_TURN_WEIGHT = 0.2  # [m/rad] heading error counted as distance when judging progress
# a noisy reading this many sigmas short is what the safety controller's band must allow for
_SAFETY_SIGMAS = 2.0
_REVERSE_MAX = 1.0  # [m] the farthest the robot backs to the pre-door point


class DoorPass:
    """Drives the robot through the first door on its path (see the module)."""

    def __init__(
        self,
        params: DoorParams,
        costmap: CostmapParams,
        dwa: DwaParams,
        back_out_speed: float,
        safety_distance: float,
        range_noise: float = 0.0,
    ):
        """costmap: the footprint's settings; dwa: the turn limits, the control rate and the
        rotation step of the motion checks; back_out_speed [m/s]: backing up for room
        (RecoveryParams.back_out_speed_ratio x escape_vel); safety_distance [m]: the safety
        controller's (SafetyParams); range_noise: the laser's range noise sigma [m]: a forward
        approach is one the safety controller would let pass with readings _SAFETY_SIGMAS of
        it short."""
        self.params = params
        self.costmap_params = costmap
        self.dwa = dwa
        self.back_out_speed = back_out_speed
        # [m] how far ahead of the footprint's front a forward approach keeps the map clear
        self.front_reach = safety_distance + _SAFETY_SIGMAS * float(range_noise)
        self.door: Door | None = None
        self.phase = "through"  # "approach" (to the pre-door point) or "through"
        self._rotating = False
        self._reverse = False  # the approach backs to the pre-door point
        self._local: LocalCostmap | None = None  # the map's obstacles around the robot
        self.n_passages = 0  # passages driven through to their far end
        self._best = (-1, -math.inf)  # (phase rank, -remaining) the best progress so far
        self._stalled = 0  # control periods since the last progress
        # centres of doors given up (door_patience) for the goal being pursued
        self.refused: list[np.ndarray] = []

    def new_goal(self) -> None:
        """A new goal: the doors given up for the last one may be tried again."""
        self.refused.clear()
        self.reset()

    def reset(self) -> None:
        self.door = None
        self.phase = "through"
        self._rotating = False
        self._reverse = False
        self._best = (-1, -math.inf)
        self._stalled = 0

    def command(
        self,
        pose: np.ndarray,
        path_xy: np.ndarray | None,
        costmap: GlobalCostmap,
        seen: LocalCostmap | None = None,
    ) -> tuple[float, float, str] | None:
        """(v, w, kind) with kind "door_turn", "door", "door_reverse" or "door_back", or
        None (no door ahead, or nothing legal: the DWA decides). Doors and motions are
        judged on the SLAM map's obstacles alone (`GlobalCostmap.map_lethal`): one scan of
        a noisy laser marks a door's jambs up to two sigmas into the opening along its
        oblique beams, the map holds where many scans agree. `seen`, the DWA's local
        costmap (the map and the laser's marks): a door takes over only where it is
        narrower there than door_engage_width (None: every door)."""
        p = self.params
        if path_xy is None or len(path_xy) < 3 or costmap.shape[0] == 0:
            self.reset()
            return None
        pts, along = path_ahead(path_xy, float(pose[0]), float(pose[1]), p)
        seen_gap = None
        if seen is not None:
            # what the DWA sees holds the map's obstacles and more: where nothing ahead is
            # tight there, no door of the map can be taken up (the map-only window is not
            # built, which is most control periods)
            seen_gap = gaps(pts, seen, p.door_width)
            if self.door is None and not (seen_gap < p.door_engage_width).any():
                return None
        local = self._map_window(pose, costmap)
        if self.door is not None:
            d = self.door
            if d.frame(pose)[0] < d.s_in and not crosses(
                pts, d.centre, d.axis, float(np.hypot(*(d.jambs[1] - d.jambs[0])))
            ):
                self.reset()  # a new plan that does not take this door
        if self.door is None:
            found = find_door(pts, along, local, p)
            if found is None or any(
                np.hypot(*(found.centre - c)) <= p.door_width for c in self.refused
            ):
                return None  # none, or given up before: the DWA and the recoveries have it
            if seen_gap is not None and not tight_near(pts, seen_gap, found, p):
                return None  # the DWA sees this door wide enough: it drives through at speed
            # the pre-door point (a few footprint spins) only for a door taken up, not for
            # each one found and left to the DWA
            pre = self._pre_door_point(
                found.centre, found.axis, found.s_in, local, pose[:2], self.front_reach
            )
            self.door = found = dataclasses.replace(found, pre=pre)
            off = found.frame(pose)[1]
            self.phase = "approach" if pre is not None and abs(off) > _ON_AXIS else "through"
        return self._drive(pose, local)

    def _map_window(self, pose: np.ndarray, costmap: GlobalCostmap) -> LocalCostmap:
        """The SLAM map's obstacles around the robot, its near / inner layers made for the
        footprint grown by door_margin."""
        c = self.costmap_params
        if self._local is None or self._local.resolution != costmap.resolution:
            padding = max(c.footprint_padding, self.params.door_margin)
            grown = dataclasses.replace(c, footprint_padding=padding)
            self._local = LocalCostmap(grown, self.dwa, costmap.resolution)
        self._local.build(float(pose[0]), float(pose[1]), costmap, float(pose[2]), map_only=True)
        return self._local

    def _drive(self, pose: np.ndarray, local: LocalCostmap) -> tuple[float, float, str] | None:
        door = self.door
        a, off = door.frame(pose)
        half = self.costmap_params.footprint_half_m
        if a > door.s_out + half + 0.05:
            self.n_passages += 1  # the robot's back is out of the door
            self.reset()
            return None
        if a < door.s_in - (self.params.door_lookahead + 0.5) or abs(off) > self.params.door_width:
            self.reset()  # the robot left the door's approach (a replan, a recovery)
            return None
        inside = a > door.s_in - half  # its front is in the tight stretch
        self._update_phase(pose, inside, off)
        dist, err, remaining = self._aim(pose, local, a, off, inside)
        if not self._progress(self.phase == "through", remaining + _TURN_WEIGHT * abs(err)):
            # lining up and backing for room got the robot no nearer: something the map
            # does not hold is in the way, or the door is too tight to line up in
            self.refused.append(door.centre.copy())
            self.reset()
            return None
        if self.phase == "through" and inside and abs(err) > 0.5 * math.pi:
            return self._reverse_through(pose, local, err)
        out = self._motion(pose, local, err, dist)
        if out is not None:
            return out
        # neither the turn nor the drive is legal here: back up along the heading for room
        v = self.back_out_speed
        if a < door.s_out and self._legal(pose, v, 0.0, local, _CHECK_TIME):
            self._rotating = False
            return v, 0.0, "door_back"
        self.reset()
        return None

    def _update_phase(self, pose: np.ndarray, inside: bool, off: float) -> None:
        """Approach the pre-door point, or go through: the phase for this period."""
        door = self.door
        if self.phase == "through" and door.pre is not None and not inside and abs(off) > _OFF_AXIS:
            self.phase = "approach"  # drifted off the axis before the door
        if self.phase == "approach":
            if inside:
                self.phase = "through"
            elif np.hypot(*(door.pre - pose[:2])) < _AT_PRE:
                self.phase = "through"
                self._rotating = False
            if self.phase == "through":
                self._reverse = False

    def _aim(self, pose: np.ndarray, local: LocalCostmap, a: float, off: float, inside: bool):
        """(distance to the phase's target [m], heading error [rad], what remains of the
        passage [m]) for this period."""
        door = self.door
        u = door.axis
        if self.phase == "approach":
            target = door.pre
            vec = target - pose[:2]
            dist = float(np.hypot(*vec))
            if (
                not self._reverse
                and dist <= _REVERSE_MAX
                and not self._front_clear(pose[:2], target, local, self.front_reach)
            ):
                # driving there forwards brings a wall into the safety controller's band
                # (a deep jamb beside the pre-door point, met at an angle): a noisy reading
                # of it stops the robot again and again; it backs there instead, facing
                # away from that wall, on a stretch its laser has just seen
                self._reverse = True
            heading = math.atan2(vec[1], vec[0]) + (math.pi if self._reverse else 0.0)
            err = wrap_angle(heading - float(pose[2]))
            return dist, err, dist + (door.s_out - door.frame(target)[0])
        half = self.costmap_params.footprint_half_m
        target = door.centre + (door.s_out + half + 0.1) * u
        dist = float(np.hypot(*(target - pose[:2])))
        limit = _LINE_MAX_INSIDE if inside else _LINE_MAX
        desired = math.atan2(u[1], u[0]) - max(-limit, min(limit, _LINE_GAIN * off))
        err = wrap_angle(desired - float(pose[2]))
        return dist, err, door.s_out - a + abs(off)

    def _reverse_through(self, pose, local: LocalCostmap, err: float):
        """In the door facing back along the axis (a new goal behind the robot while it was
        passing): drive backwards through it rather than turn round in it, where the
        footprint's diagonal (1.41 times its side) may stick across the door."""
        dwa = self.dwa
        back_err = wrap_angle(err + math.pi)  # the rear's heading turns with w as well
        self._rotating = False
        v = -self.params.door_speed
        w = max(-dwa.max_vel_theta, min(dwa.max_vel_theta, _STEER_GAIN * back_err))
        if self._legal(pose, v, w, local, _CHECK_TIME):
            return v, w, "door_reverse"
        self.reset()
        return None

    def _motion(self, pose, local: LocalCostmap, err: float, dist: float):
        """(v, w, kind) that turns towards, or drives along, the heading error `err`, if
        legal; None when neither is."""
        p, dwa = self.params, self.dwa
        threshold = 0.5 * p.door_angle if self._rotating else p.door_angle
        if abs(err) > threshold:
            w_mag = max(dwa.min_in_place_vel_theta, min(dwa.max_vel_theta, 2.0 * abs(err)))
            w = math.copysign(w_mag, err)
            if self._legal(pose, 0.0, w, local, min(_CHECK_TIME, abs(err) / w_mag + 0.1)):
                self._rotating = True
                return 0.0, w, "door_turn"
        else:
            self._rotating = False
            v = p.door_speed if self.phase == "through" else min(p.door_speed, max(0.05, dist))
            w = max(-dwa.max_vel_theta, min(dwa.max_vel_theta, _STEER_GAIN * err))
            check = _CHECK_TIME if self.phase == "through" else min(_CHECK_TIME, dist / v)
            if self.phase == "approach" and self._reverse:
                v = -v  # err is the rear's heading error: w turns it the same way
            if self._legal(pose, v, w, local, check):
                return v, w, "door" if v > 0.0 else "door_reverse"
        return None

    def _progress(self, through: bool, remaining: float) -> bool:
        """Record this period's progress; False once there was none for door_patience."""
        key = (int(through), -remaining)
        if key[0] > self._best[0] or key[1] > self._best[1] + 0.05:
            self._best, self._stalled = key, 0
        else:
            self._stalled += 1
        return self._stalled <= self.params.door_patience * self.dwa.controller_frequency

    def _pre_door_point(self, centre, u, s_in: float, local: LocalCostmap, start=None, reach=0.0):
        """The nearest point on the axis before the door (_PRE_DISTANCES before its entry)
        where the footprint grown by door_margin, facing along the axis, fits and can turn on
        the spot and which the robot at `start` (None: not asked) can drive to forwards with
        the map's obstacles out of the safety band `reach` [m] ahead of it (`_front_clear`);
        failing that, the nearest where it fits and can turn; failing that, where it fits at
        all; or None."""
        th = math.atan2(u[1], u[0])
        half = self.costmap_params.footprint_half_m + self.params.door_margin
        spin = 2.0 * math.pi
        fits: list[np.ndarray] = []
        for dist in _PRE_DISTANCES:
            q = centre + (s_in - dist) * u
            if self._motion_legal(q, th, 0.0, 1.0, spin, local, half):
                if start is None or self._front_clear(start, q, local, reach):
                    return q
                fits.append(q)
        if fits:
            return fits[0]
        for dist in _PRE_DISTANCES:
            q = centre + (s_in - dist) * u
            if self._motion_legal(q, th, 0.0, 0.0, 0.0, local, half):
                return q
        return None

    def _front_clear(self, start, end, local: LocalCostmap, reach: float) -> bool:
        """Whether the robot driving straight from `start` to `end` [m], facing `end`, keeps
        every obstacle cell of `local` out of the safety controller's band (`safety.
        front_clearance`: ahead of the footprint's front by less than `reach` [m], within its
        half side plus footprint_padding across) at every point of the way (every half
        cell)."""
        c = self.costmap_params
        return front_clear(start, end, local, c.footprint_half_m, c.footprint_padding, reach)

    def _legal(self, pose, v: float, w: float, local: LocalCostmap, duration: float) -> bool:
        """Driving (v, w) for `duration` [s] keeps the footprint grown by door_margin (the
        SLAM pose's error; no DWA padding: these are slow, finely checked motions) clear of
        the map's obstacles around the robot."""
        half = self.costmap_params.footprint_half_m + self.params.door_margin
        return self._motion_legal(pose[:2], float(pose[2]), v, w, duration, local, half)

    def _motion_legal(self, xy, th: float, v: float, w: float, duration: float, local, half):
        return dk.motion_legal(
            float(xy[0]), float(xy[1]), th, v, w, duration, local.lethal, local.near,
            local.inner, float(local.origin[0]), float(local.origin[1]), local.resolution,
            half, self.dwa.angular_sim_granularity,
        )  # fmt: skip


def front_clear(start, end, local: LocalCostmap, half: float, padding: float, reach: float):
    """`DoorPass._front_clear` for a footprint of half side `half` [m] with `padding` [m]."""
    start = np.asarray(start, dtype=float)
    vec = np.asarray(end, dtype=float) - start
    n = float(np.hypot(*vec))
    if n < 1e-6:
        return True
    u = vec / n
    res = local.resolution
    iy, ix = np.nonzero(local.lethal)
    cx = local.origin[0] + (ix + 0.5) * res - start[0]
    cy = local.origin[1] + (iy + 0.5) * res - start[1]
    near = np.hypot(cx, cy) <= n + half + reach + 2.0 * half + res
    cx, cy = cx[near], cy[near]
    if len(cx) == 0:
        return True
    s = np.linspace(0.0, n, int(n / (0.5 * res)) + 2)
    along = (cx * u[0] + cy * u[1])[None, :] - s[:, None]
    across = np.abs(u[0] * cy - u[1] * cx)[None, :]
    # a cell counts from its near face (half a cell nearer than its centre)
    ahead = along - half - 0.5 * res
    band = (along > half) & (ahead < reach) & (across < half + padding)
    return not bool(band.any())
