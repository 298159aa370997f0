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

On with a noisy laser (`explore.noisy_door_align`, `ExploreParams.for_range_noise`), off on
a noise-free one (`explore.door_align`), where it makes explorations 20 % longer for no
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
from scipy import ndimage

from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.explore import door_kernels as dok
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.params import ExploreParams

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
_TRIES = 4  # places of one tight stretch of the path tried as a door at most
# a noisy reading this many sigmas short is what the safety controller's band must allow for
_SAFETY_SIGMAS = 2.0
_REVERSE_MAX = 1.0  # [m] the farthest the robot backs to the pre-door point


@dataclasses.dataclass(frozen=True)
class Door:
    """A door found on the path: its centre and unit axis (the way the path crosses it), the
    stretch along the axis where it is tight (s_in < 0 < s_out [m] from the centre), its
    jambs (the nearest obstacle cell centres on the left and on the right), its clear width
    and the pre-door point (None: no place on the axis before it fits the footprint, or not
    looked for: `find_door` leaves that to the passage that takes the door up)."""

    centre: np.ndarray
    axis: np.ndarray
    s_in: float
    s_out: float
    jambs: tuple[np.ndarray, np.ndarray]
    width: float
    pre: np.ndarray | None = None

    def frame(self, xy) -> tuple[float, float]:
        """(along the axis from the centre, left of it) [m] of the point xy."""
        rel = np.asarray(xy[:2], dtype=float) - self.centre
        u = self.axis
        return float(u @ rel), float(u[0] * rel[1] - u[1] * rel[0])


class DoorPass:
    """Drives the robot through the first door on its path (see the module)."""

    def __init__(self, params: ExploreParams, range_noise: float = 0.0):
        """range_noise: the laser's range noise sigma [m]: a forward approach is one the
        safety controller would let pass with readings _SAFETY_SIGMAS of it short."""
        self.params = params
        # [m] how far ahead of the footprint's front a forward approach keeps the map clear
        self.front_reach = params.safety_distance + _SAFETY_SIGMAS * float(range_noise)
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
        pts, along = _ahead(path_xy, float(pose[0]), float(pose[1]), p)
        seen_gap = None
        if seen is not None:
            # what the DWA sees holds the map's obstacles and more: where nothing ahead is
            # tight there, no door of the map can be taken up (the map-only window is not
            # built, which is most control periods)
            seen_gap = _gaps(pts, seen)
            if self.door is None and not (seen_gap < p.door_engage_width).any():
                return None
        local = self._map_window(pose, costmap)
        if self.door is not None:
            d = self.door
            if d.frame(pose)[0] < d.s_in and not _crosses(
                pts, d.centre, d.axis, float(np.hypot(*(d.jambs[1] - d.jambs[0])))
            ):
                self.reset()  # a new plan that does not take this door
        if self.door is None:
            found = find_door(pts, along, local, p)
            if found is None or any(
                np.hypot(*(found.centre - c)) <= p.door_width for c in self.refused
            ):
                return None  # none, or given up before: the DWA and the recoveries have it
            if seen_gap is not None and not _tight_near(pts, seen_gap, found, p):
                return None  # the DWA sees this door wide enough: it drives through at speed
            # the pre-door point (a few footprint spins) only for a door taken up, not for
            # each one found and left to the DWA
            pre = _pre_door_point(
                found.centre, found.axis, found.s_in, local, p, pose[:2], self.front_reach
            )
            self.door = found = dataclasses.replace(found, pre=pre)
            off = found.frame(pose)[1]
            self.phase = "approach" if pre is not None and abs(off) > _ON_AXIS else "through"
        return self._drive(pose, local)

    def _map_window(self, pose: np.ndarray, costmap: GlobalCostmap) -> LocalCostmap:
        """The SLAM map's obstacles around the robot, its near / inner layers made for the
        footprint grown by door_margin."""
        p = self.params
        if self._local is None or self._local.resolution != costmap.resolution:
            padding = max(p.footprint_padding, p.door_margin)
            grown = dataclasses.replace(p, footprint_padding=padding).with_footprint(
                2.0 * p.footprint_half_m
            )
            self._local = LocalCostmap(grown, costmap.resolution)
        self._local.build(float(pose[0]), float(pose[1]), costmap, float(pose[2]), map_only=True)
        return self._local

    def _drive(self, pose: np.ndarray, local: LocalCostmap) -> tuple[float, float, str] | None:
        p = self.params
        door = self.door
        a, off = door.frame(pose)
        half = p.footprint_half_m
        if a > door.s_out + half + 0.05:
            self.n_passages += 1  # the robot's back is out of the door
            self.reset()
            return None
        if a < door.s_in - (p.door_lookahead + 0.5) or abs(off) > p.door_width:
            self.reset()  # the robot left the door's approach (a replan, a recovery)
            return None
        inside = a > door.s_in - half  # its front is in the tight stretch
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
        u = door.axis
        if self.phase == "approach":
            target = door.pre
            vec = target - pose[:2]
            dist = float(np.hypot(*vec))
            if (
                not self._reverse
                and dist <= _REVERSE_MAX
                and not _front_clear(pose[:2], target, local, p, self.front_reach)
            ):
                # driving there forwards brings a wall into the safety controller's band
                # (a deep jamb beside the pre-door point, met at an angle): a noisy reading
                # of it stops the robot again and again; it backs there instead, facing
                # away from that wall, on a stretch its laser has just seen
                self._reverse = True
            heading = math.atan2(vec[1], vec[0]) + (math.pi if self._reverse else 0.0)
            err = wrap_angle(heading - float(pose[2]))
            remaining = dist + (door.s_out - door.frame(target)[0])
        else:
            target = door.centre + (door.s_out + half + 0.1) * u
            dist = float(np.hypot(*(target - pose[:2])))
            limit = _LINE_MAX_INSIDE if inside else _LINE_MAX
            desired = math.atan2(u[1], u[0]) - max(-limit, min(limit, _LINE_GAIN * off))
            err = wrap_angle(desired - float(pose[2]))
            remaining = door.s_out - a + abs(off)
        if not self._progress(self.phase == "through", remaining + _TURN_WEIGHT * abs(err)):
            # lining up and backing for room got the robot no nearer: something the map
            # does not hold is in the way, or the door is too tight to line up in
            self.refused.append(door.centre.copy())
            self.reset()
            return None
        if self.phase == "through" and inside and abs(err) > 0.5 * math.pi:
            # in the door facing back along the axis (a new goal behind the robot while it
            # was passing): drive backwards through it rather than turn round in it, where
            # the footprint's diagonal (1.41 times its side) may stick across the door
            back_err = wrap_angle(err + math.pi)  # the rear's heading turns with w as well
            self._rotating = False
            v = -p.door_speed
            w = max(-p.max_vel_theta, min(p.max_vel_theta, _STEER_GAIN * back_err))
            if _legal(pose, v, w, local, p, _CHECK_TIME):
                return v, w, "door_reverse"
            self.reset()
            return None
        threshold = 0.5 * p.door_angle if self._rotating else p.door_angle
        if abs(err) > threshold:
            w_mag = max(p.min_in_place_vel_theta, min(p.max_vel_theta, 2.0 * abs(err)))
            w = math.copysign(w_mag, err)
            if _legal(pose, 0.0, w, local, p, min(_CHECK_TIME, abs(err) / w_mag + 0.1)):
                self._rotating = True
                return 0.0, w, "door_turn"
        else:
            self._rotating = False
            v = p.door_speed if self.phase == "through" else min(p.door_speed, max(0.05, dist))
            w = max(-p.max_vel_theta, min(p.max_vel_theta, _STEER_GAIN * err))
            check = _CHECK_TIME if self.phase == "through" else min(_CHECK_TIME, dist / v)
            if self.phase == "approach" and self._reverse:
                v = -v  # err is the rear's heading error: w turns it the same way
            if _legal(pose, v, w, local, p, check):
                return v, w, "door" if v > 0.0 else "door_reverse"
        # neither the turn nor the drive is legal here: back up along the heading for room
        v = p.back_out_speed_ratio * p.escape_vel
        if a < door.s_out and _legal(pose, v, 0.0, local, p, _CHECK_TIME):
            self._rotating = False
            return v, 0.0, "door_back"
        self.reset()
        return None

    def _progress(self, through: bool, remaining: float) -> bool:
        """Record this period's progress; False once there was none for door_patience."""
        key = (int(through), -remaining)
        if key[0] > self._best[0] or key[1] > self._best[1] + 0.05:
            self._best, self._stalled = key, 0
        else:
            self._stalled += 1
        return self._stalled <= self.params.door_patience * self.params.controller_frequency


def _ahead(path_xy: np.ndarray, x: float, y: float, p: ExploreParams):
    """The path from its point nearest (x, y) on, door_lookahead + 2 door_width [m] of it,
    and the distance [m] along it of each point."""
    d = np.hypot(path_xy[:, 0] - x, path_xy[:, 1] - y)
    i0 = int(np.argmin(d))
    seg = np.hypot(*np.diff(path_xy[i0:], axis=0).T)
    along = np.concatenate(([0.0], np.cumsum(seg)))
    end = int(np.searchsorted(along, p.door_lookahead + 2.0 * p.door_width, side="right"))
    return np.ascontiguousarray(path_xy[i0 : i0 + end], dtype=float), along[:end]


def _gaps_rows(pts: np.ndarray, local: LocalCostmap, cone: float) -> np.ndarray:
    """`door_kernels.gaps_along` on `local`'s obstacles out to door_width: `(K, 6)`."""
    return dok.gaps_along(
        np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), local.lethal,
        float(local.origin[0]), float(local.origin[1]), local.resolution,
        local.params.door_width, cone,
    )  # fmt: skip


def _gaps(pts: np.ndarray, local: LocalCostmap, cone: float = dok.ACROSS_PATH) -> np.ndarray:
    """`(K,)` [m]: the clear width across the path at each point, between the nearest
    obstacle cells of `local` on its left and on its right within `cone` of its normal
    (inf where a side has none within door_width)."""
    if len(pts) < 3:
        return np.full(len(pts), np.inf)
    rows = _gaps_rows(pts, local, cone)
    return rows[:, 2] + rows[:, 5] - local.resolution


def _tight_near(pts: np.ndarray, seen_gap: np.ndarray, door: Door, p: ExploreParams) -> bool:
    """Whether the path, where it passes the door (within door_width of its centre), is
    narrower than door_engage_width as the DWA sees it."""
    near = np.hypot(pts[:, 0] - door.centre[0], pts[:, 1] - door.centre[1]) <= p.door_width
    return bool((seen_gap[near] < p.door_engage_width).any())


def find_door(pts: np.ndarray, along: np.ndarray, local: LocalCostmap, p: ExploreParams):
    """The first door narrower than door_width on the path ahead (`_ahead`: `pts`, `along`)
    that the path enters within door_lookahead (the robot possibly in it already), as a
    `Door`, or None. A path point is in a passage when the nearest obstacle cells of
    `local` (the map's obstacles around the robot) on its left and on its right, across the
    path, leave less than door_width between them; the passage is a door when, refined to
    its jambs (`_door_at`), the path crosses the line between them and both jambs belong to
    walls (`_in_walls`)."""
    if len(pts) < 3:
        return None
    rows = _gaps_rows(pts, local, dok.ACROSS_PATH)
    gap = rows[:, 2] + rows[:, 5] - local.resolution
    tight = gap < p.door_width
    comps = None
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
        # the narrowest points of the stretch first, each one apart from those tried (a
        # stretch may run from a door on into the furniture past it)
        tried: list[np.ndarray] = []
        for j in i1 + np.argsort(gap[i1 : i2 + 1], kind="stable"):
            if len(tried) == _TRIES:
                break
            if any(np.hypot(*(pts[j] - q)) < 0.5 * p.door_width for q in tried):
                continue
            tried.append(pts[j])
            door = _door_at(pts, int(j), rows[j], local, p)
            if door is not None:
                comps = _components(local.lethal) if comps is None else comps
                if _in_walls(door, local, comps, p):
                    return door
        i = i2 + 1
    return None


def _door_at(pts: np.ndarray, j: int, row: np.ndarray, local: LocalCostmap, p: ExploreParams):
    """The `Door` through the tight point pts[j] (its `gaps_along` row), or None when the
    path does not cross the line between the jambs or the refined door is not tight. The
    jambs are refined from the door's own centre and axis: the nearest obstacle cells across
    the axis from the midpoint of the last pair, until they stay put (a door the plan crosses
    diagonally is found from the cells nearest the plan, which need not face each other)."""
    res = local.resolution
    ox, oy = float(local.origin[0]), float(local.origin[1])
    a, b = row[0:2].copy(), row[3:5].copy()  # left, right of the path
    d = _direction_at(pts, pts[j])
    u = d
    for _ in range(4):
        ab = b - a
        n = float(np.hypot(*ab))
        if n == 0.0:
            return None
        u = np.array([-ab[1], ab[0]]) / n  # a (left) to b (right): u points along the path
        if u @ d < 0.0:
            return None  # the jambs swapped sides: no door across this path
        c = 0.5 * (a + b)
        lx, ly, ld, rx, ry, rd = dok.nearest_sides(
            c[0], c[1], u[0], u[1], local.lethal, ox, oy, res, p.door_width, dok.ACROSS_PATH
        )
        if not (math.isfinite(ld) and math.isfinite(rd)):
            break
        a2, b2 = np.array([lx, ly]), np.array([rx, ry])
        if np.array_equal(a2, a) and np.array_equal(b2, b):
            break
        a, b = a2, b2
    centre = 0.5 * (a + b)
    width = float(np.hypot(*(b - a))) - res
    if width >= p.door_width or not _crosses(pts, centre, u, float(np.hypot(*(b - a)))):
        return None
    s_in, s_out = _tight_stretch(centre, u, local, p)
    return Door(centre, u, s_in, s_out, (a, b), width)


def _crosses(pts: np.ndarray, centre: np.ndarray, u: np.ndarray, span: float) -> bool:
    """Whether the path crosses the door's line (through `centre`, across the axis `u`)
    between its jambs (`span` [m] apart) in the direction of u."""
    rel = pts - centre
    s = rel @ u
    t = rel[:, 0] * -u[1] + rel[:, 1] * u[0]  # along the door's line
    k = np.nonzero((s[:-1] < 0.0) & (s[1:] >= 0.0))[0]
    for i in k:
        f = -s[i] / (s[i + 1] - s[i])
        if abs(t[i] + f * (t[i + 1] - t[i])) <= 0.5 * span:
            return True
    return False


def _tight_stretch(centre, u, local: LocalCostmap, p: ExploreParams) -> tuple[float, float]:
    """(s_in, s_out) [m]: the stretch of the axis around the centre, sampled every half
    cell, where the clear width across it (its cross-section, ACROSS_AXIS) stays under
    door_width."""
    step = 0.5 * local.resolution
    s = np.arange(-p.door_width, p.door_width + 0.5 * step, step)
    line = centre + s[:, None] * u
    # the kernel takes the direction from neighbouring points: a straight line along u
    gap = _gaps(line, local, dok.ACROSS_AXIS)
    i0 = int(np.argmin(np.abs(s)))
    lo = hi = i0
    while lo > 0 and gap[lo - 1] < p.door_width:
        lo -= 1
    while hi + 1 < len(s) and gap[hi + 1] < p.door_width:
        hi += 1
    return float(s[lo]), float(s[hi])


def _pre_door_point(
    centre, u, s_in: float, local: LocalCostmap, p: ExploreParams, start=None, reach=0.0
):
    """The nearest point on the axis before the door (_PRE_DISTANCES before its entry) where
    the footprint grown by door_margin, facing along the axis, fits and can turn on the spot
    and which the robot at `start` (None: not asked) can drive to forwards with the map's
    obstacles out of the safety band `reach` [m] ahead of it (`_front_clear`); failing
    that, the nearest where it fits and can turn; failing that, where it fits at all; or
    None."""
    th = math.atan2(u[1], u[0])
    half = p.footprint_half_m + p.door_margin
    spin = 2.0 * math.pi
    fits: list[np.ndarray] = []
    for dist in _PRE_DISTANCES:
        q = centre + (s_in - dist) * u
        if _motion_legal(q, th, 0.0, 1.0, spin, local, half, p):
            if start is None or _front_clear(start, q, local, p, reach):
                return q
            fits.append(q)
    if fits:
        return fits[0]
    for dist in _PRE_DISTANCES:
        q = centre + (s_in - dist) * u
        if _motion_legal(q, th, 0.0, 0.0, 0.0, local, half, p):
            return q
    return None


def _front_clear(start, end, local: LocalCostmap, p: ExploreParams, reach: float) -> bool:
    """Whether the robot driving straight from `start` to `end` [m], facing `end`, keeps
    every obstacle cell of `local` out of the safety controller's band (`safety.
    front_clearance`: ahead of the footprint's front by less than `reach` [m], within its
    half side plus footprint_padding across) at every point of the way (every half cell)."""
    start = np.asarray(start, dtype=float)
    vec = np.asarray(end, dtype=float) - start
    n = float(np.hypot(*vec))
    if n < 1e-6:
        return True
    u = vec / n
    half = p.footprint_half_m
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
    band = (along > half) & (ahead < reach) & (across < half + p.footprint_padding)
    return not bool(band.any())


def _components(lethal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(labels, extent [cells] of each label): the 8-connected obstacle regions of `lethal`
    and the longer side of each one's bounding box."""
    labels, n = ndimage.label(lethal, structure=np.ones((3, 3), dtype=bool))
    extent = np.zeros(n + 1)
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        extent[k] = max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start)
    return labels, extent


def _in_walls(door: Door, local: LocalCostmap, comps, p: ExploreParams) -> bool:
    """Whether both jambs belong to obstacle regions at least door_wall_min long: a door in
    a wall, not a gap between pieces of furniture."""
    labels, extent = comps
    res = local.resolution
    h, w = labels.shape
    for jamb in door.jambs:
        ix = int(math.floor((jamb[0] - local.origin[0]) / res))
        iy = int(math.floor((jamb[1] - local.origin[1]) / res))
        if not (0 <= ix < w and 0 <= iy < h):
            return False
        label = labels[iy, ix]
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
    """Driving (v, w) for `duration` [s] keeps the footprint grown by door_margin (the SLAM
    pose's error; no DWA padding: these are slow, finely checked motions) clear of the
    map's obstacles around the robot."""
    half = p.footprint_half_m + p.door_margin
    return _motion_legal(pose[:2], float(pose[2]), v, w, duration, local, half, p)


def _motion_legal(xy, th: float, v: float, w: float, duration: float, local, half: float, p):
    return dk.motion_legal(
        float(xy[0]), float(xy[1]), th, v, w, duration, local.lethal, local.near,
        local.inner, float(local.origin[0]), float(local.origin[1]), local.resolution, half,
        p.angular_sim_granularity,
    )  # fmt: skip
