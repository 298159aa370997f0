"""Doors on the path: where the path crosses a wall's gap narrower than door_width, its jambs,
centre, axis and tight stretch, found on the SLAM map's obstacles around the robot (the door
passage's judge, `door.DoorPass`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy import ndimage

from worker.explore import door_kernels as dok
from worker.explore.costmap import LocalCostmap
from worker.explore.params import DoorParams

_TRIES = 4  # places of one tight stretch of the path tried as a door at most


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


def path_ahead(path_xy: np.ndarray, x: float, y: float, p: DoorParams):
    """The path from its point nearest (x, y) on, door_lookahead + 2 door_width [m] of it,
    and the distance [m] along it of each point."""
    d = np.hypot(path_xy[:, 0] - x, path_xy[:, 1] - y)
    i0 = int(np.argmin(d))
    seg = np.hypot(*np.diff(path_xy[i0:], axis=0).T)
    along = np.concatenate(([0.0], np.cumsum(seg)))
    end = int(np.searchsorted(along, p.door_lookahead + 2.0 * p.door_width, side="right"))
    return np.ascontiguousarray(path_xy[i0 : i0 + end], dtype=float), along[:end]


def _gaps_rows(pts: np.ndarray, local: LocalCostmap, reach: float, cone: float) -> np.ndarray:
    """`door_kernels.gaps_along` on `local`'s obstacles out to `reach` [m] (door_width):
    `(K, 6)`."""
    return dok.gaps_along(
        np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), local.lethal,
        float(local.origin[0]), float(local.origin[1]), local.resolution,
        reach, cone,
    )  # fmt: skip


def gaps(
    pts: np.ndarray, local: LocalCostmap, reach: float, cone: float = dok.ACROSS_PATH
) -> np.ndarray:
    """`(K,)` [m]: the clear width across the path at each point, between the nearest
    obstacle cells of `local` on its left and on its right within `cone` of its normal
    (inf where a side has none within `reach` [m], door_width)."""
    if len(pts) < 3:
        return np.full(len(pts), np.inf)
    rows = _gaps_rows(pts, local, reach, cone)
    return rows[:, 2] + rows[:, 5] - local.resolution


def tight_near(pts: np.ndarray, seen_gap: np.ndarray, door: Door, p: DoorParams) -> bool:
    """Whether the path, where it passes the door (within door_width of its centre), is
    narrower than door_engage_width as the DWA sees it."""
    near = np.hypot(pts[:, 0] - door.centre[0], pts[:, 1] - door.centre[1]) <= p.door_width
    return bool((seen_gap[near] < p.door_engage_width).any())


def find_door(pts: np.ndarray, along: np.ndarray, local: LocalCostmap, p: DoorParams):
    """The first door narrower than door_width on the path ahead (`path_ahead`: `pts`, `along`)
    that the path enters within door_lookahead (the robot possibly in it already), as a
    `Door`, or None. A path point is in a passage when the nearest obstacle cells of
    `local` (the map's obstacles around the robot) on its left and on its right, across the
    path, leave less than door_width between them; the passage is a door when, refined to
    its jambs (`_door_at`), the path crosses the line between them and both jambs belong to
    walls (`_in_walls`)."""
    if len(pts) < 3:
        return None
    rows = _gaps_rows(pts, local, p.door_width, dok.ACROSS_PATH)
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


def _door_at(pts: np.ndarray, j: int, row: np.ndarray, local: LocalCostmap, p: DoorParams):
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
    if width >= p.door_width or not crosses(pts, centre, u, float(np.hypot(*(b - a)))):
        return None
    s_in, s_out = _tight_stretch(centre, u, local, p)
    return Door(centre, u, s_in, s_out, (a, b), width)


def crosses(pts: np.ndarray, centre: np.ndarray, u: np.ndarray, span: float) -> bool:
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


def _tight_stretch(centre, u, local: LocalCostmap, p: DoorParams) -> tuple[float, float]:
    """(s_in, s_out) [m]: the stretch of the axis around the centre, sampled every half
    cell, where the clear width across it (its cross-section, ACROSS_AXIS) stays under
    door_width."""
    step = 0.5 * local.resolution
    s = np.arange(-p.door_width, p.door_width + 0.5 * step, step)
    line = centre + s[:, None] * u
    # the kernel takes the direction from neighbouring points: a straight line along u
    gap = gaps(line, local, p.door_width, dok.ACROSS_AXIS)
    i0 = int(np.argmin(np.abs(s)))
    lo = hi = i0
    while lo > 0 and gap[lo - 1] < p.door_width:
        lo -= 1
    while hi + 1 < len(s) and gap[hi + 1] < p.door_width:
        hi += 1
    return float(s[lo]), float(s[hi])


def _components(lethal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(labels, extent [cells] of each label): the 8-connected obstacle regions of `lethal`
    and the longer side of each one's bounding box."""
    labels, n = ndimage.label(lethal, structure=np.ones((3, 3), dtype=bool))
    extent = np.zeros(n + 1)
    for k, sl in enumerate(ndimage.find_objects(labels), start=1):
        extent[k] = max(sl[0].stop - sl[0].start, sl[1].stop - sl[1].start)
    return labels, extent


def _in_walls(door: Door, local: LocalCostmap, comps, p: DoorParams) -> bool:
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
