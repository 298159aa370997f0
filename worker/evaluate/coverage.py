"""Explored coverage: share of the floorplan's reachable free area the SLAM map marks free."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from worker.distance_kernels import inflate_region
from worker.evaluate.ate import align_se2

_FOUR = ndimage.generate_binary_structure(2, 1)


def reachable_free(
    occ: np.ndarray,
    resolution: float,
    start_cell: tuple[int, int],
    half_side: float,
    clearance: float | None = None,
) -> np.ndarray:
    """`(H, W) bool` free cells the robot can map: near where its centre can go.

    occ: (H, W) bool world grid (True obstacle), start_cell (ix, iy). The robot's centre can
    reach the 4-connected cells of clearance [m] above `clearance` (default: the footprint's
    half side) that contain the start; a free cell counts when it lies within the
    circumscribed radius plus a cell of that set (the robot's body sweeps it). Free space
    behind gaps narrower than twice the clearance is left out: the robot cannot get there,
    whatever it glimpses through the gap.
    """
    clearance = half_side if clearance is None else clearance
    free = ~occ
    # the centre is clear where the nearest obstacle (the plan's edge too) lies farther than
    # `clearance` + half a cell: (d - 0.5) * resolution > clearance, d between cell centres
    obstacles = np.pad(occ, 1, constant_values=True)
    blocked = _near(obstacles, clearance / resolution + 0.5,
                    lambda d: (d - 0.5) * resolution <= clearance)  # fmt: skip
    centre_ok = ~blocked[1:-1, 1:-1]
    del obstacles, blocked
    labels, _ = ndimage.label(centre_ok, structure=_FOUR)
    ix, iy = start_cell
    lab = labels[iy, ix] if (0 <= iy < occ.shape[0] and 0 <= ix < occ.shape[1]) else 0
    if lab == 0:
        # start cell too tight (hugging a wall): take the nearest centre-reachable component
        if not centre_ok.any():
            return np.zeros_like(occ)
        _, (ny, nx) = ndimage.distance_transform_edt(~centre_ok, return_indices=True)
        lab = labels[ny[iy, ix], nx[iy, ix]]
    reach = labels == lab
    del labels, centre_ok
    sweep = half_side * math.sqrt(2.0) + resolution  # [m] the body's reach from its centre
    return free & _near(reach, sweep / resolution, lambda d: d * resolution <= sweep)


_BAND = 256  # rows per kernel call: its row distances cover a band, not the whole plan


def _near(sources: np.ndarray, reach_cells: float, test) -> np.ndarray:
    """`(H, W) bool`: whether `test(d)` holds for each cell's distance d [cells, between
    centres] to the nearest `sources` cell, False where none lies within `reach_cells` (`test`
    must be False past it). `test` gets `np.sqrt` of the exact integer squared distance, as
    scipy's exact transform computes it, so the answer is the whole-plan transform's, in one
    byte a cell plus a band's row distances."""
    r = int(math.ceil(reach_cells)) + 1
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    d2 = dy * dy + dx * dx
    stamp = (test(np.sqrt(d2.astype(np.float64))) & (d2 <= r * r)).astype(np.uint8)
    out = np.zeros(sources.shape, dtype=np.uint8)
    h, w = sources.shape
    for y0 in range(0, h, _BAND):
        inflate_region(sources, stamp, out, y0, min(h, y0 + _BAND), 0, w)
    return out.view(np.bool_)


def align_map_to_world(pose_est: np.ndarray, pose_gt: np.ndarray) -> np.ndarray:
    """T_world_map `(3,)` [x, y, theta] aligning the estimated path onto the ground truth.

    Least squares over all positions (both `(N, 3)`, same timestamps); with fewer than two
    distinct positions, the transform that maps the first estimated pose onto the first
    ground-truth pose.
    """
    if len(pose_est) >= 2 and np.ptp(pose_gt[:, :2], axis=0).max() > 0.5:
        return align_se2(pose_est[:, :2], pose_gt[:, :2])
    th = pose_gt[0, 2] - pose_est[0, 2]
    c, s = math.cos(th), math.sin(th)
    x = pose_gt[0, 0] - (c * pose_est[0, 0] - s * pose_est[0, 1])
    y = pose_gt[0, 1] - (s * pose_est[0, 0] + c * pose_est[0, 1])
    return np.array([x, y, th])


class ReachCells:
    """The `reachable (H, W) bool` world cells, found once: the coverage read every
    coverage_period costs the reachable cells, not a pass over the world grid. Held as int32
    indices (8 bytes a cell) and mapped onto the SLAM grid `_CHUNK` cells at a time, so a
    whole-plan read holds a chunk's float64 scratch, not the whole set's."""

    def __init__(self, reachable: np.ndarray, world_resolution: float, world_origin):
        self.shape = reachable.shape
        ys, xs = [], []
        for y0 in range(0, reachable.shape[0], _BAND):  # np.nonzero's order, band by band
            iy, ix = np.nonzero(reachable[y0 : y0 + _BAND])
            ys.append((iy + y0).astype(np.int32))
            xs.append(ix.astype(np.int32))
        self.iy = np.concatenate(ys) if ys else np.zeros(0, dtype=np.int32)
        self.ix = np.concatenate(xs) if xs else np.zeros(0, dtype=np.int32)
        self.resolution = float(world_resolution)
        self.origin = np.asarray(world_origin, dtype=np.float64)

    def chunks(self, prob, map_resolution, map_origin, occ_thresh, T_world_map):
        """`(iy, ix, free)` per chunk of the reachable cells: the world cells whose centre
        falls on the map, and whether on a free map cell (arguments as `seen_free`)."""
        c, s = math.cos(T_world_map[2]), math.sin(T_world_map[2])
        h, w = prob.shape
        for a in range(0, self.iy.size, _CHUNK):
            iy, ix = self.iy[a : a + _CHUNK], self.ix[a : a + _CHUNK]
            xw = self.origin[0] + (ix + 0.5) * self.resolution - T_world_map[0]
            yw = self.origin[1] + (iy + 0.5) * self.resolution - T_world_map[1]
            xm = c * xw + s * yw  # R^T (p_world - t)
            ym = -s * xw + c * yw
            del xw, yw
            mx = np.floor((xm - map_origin[0]) / map_resolution).astype(np.int64)
            my = np.floor((ym - map_origin[1]) / map_resolution).astype(np.int64)
            del xm, ym
            inside = (mx >= 0) & (mx < w) & (my >= 0) & (my < h)
            p = prob[my[inside], mx[inside]]
            yield iy[inside], ix[inside], ~np.isnan(p) & (p <= occ_thresh)

    def coverage(self, *args) -> float:
        """Share of the reachable cells whose centre falls on a free map cell (arguments as
        `seen_free`)."""
        n = self.iy.size
        if n == 0:
            return 0.0
        return sum(np.count_nonzero(free) for _, _, free in self.chunks(*args)) / n


_CHUNK = 1 << 18  # reachable cells mapped at a time (about 20 MiB of float64 scratch)


def seen_free(
    reachable: np.ndarray,
    world_resolution: float,
    world_origin: np.ndarray,
    prob: np.ndarray,
    map_resolution: float,
    map_origin: np.ndarray,
    occ_thresh: float,
    T_world_map: np.ndarray,
    cells: ReachCells | None = None,
) -> np.ndarray:
    """`(H, W) bool`: the `reachable` world cells whose centre falls on a free map cell.

    prob: (h, w) SLAM probabilities (NaN unknown; free at or below occ_thresh), in the map
    frame placed in the world by T_world_map `(3,)`. cells: `ReachCells(reachable, ...)`
    when the caller holds it already.
    """
    out = np.zeros_like(reachable, dtype=np.bool_)
    if cells is None:
        cells = ReachCells(reachable, world_resolution, world_origin)
    for iy, ix, free in cells.chunks(prob, map_resolution, map_origin, occ_thresh, T_world_map):
        out[iy, ix] = free
    return out


def coverage(reachable: np.ndarray, world_resolution: float, world_origin, *args) -> float:
    """Share of `reachable (H, W)` world cells whose centre falls on a free cell of the map
    (arguments as `seen_free`)."""
    return ReachCells(reachable, world_resolution, world_origin).coverage(*args)


@dataclass(frozen=True)
class UnseenRegion:
    """A piece of reachable free space the map never showed free."""

    area_m2: float  # [m^2]
    centre: tuple[float, float]  # [m] world frame, its centroid


def unseen_regions(
    reachable: np.ndarray,
    seen: np.ndarray,
    resolution: float,
    origin: np.ndarray,
    min_area: float,
    min_width: float,
) -> list[UnseenRegion]:
    """Reachable, unseen regions at least `min_width` [m] wide and `min_area` [m^2] large,
    largest first: rooms never entered, not the slivers along walls and behind furniture
    legs that no viewpoint shows (nor the map's misalignment shows as unseen).

    reachable, seen: `(H, W) bool` world grids (`reachable_free`, `seen_free`). A region is
    an 8-connected component of what remains of reachable & ~seen after an opening by a disc
    of diameter min_width (the slivers go, a room stays).
    """
    unseen = reachable & ~seen
    r = max(1, int(round(0.5 * min_width / resolution)))
    yy, xx = np.mgrid[-r : r + 1, -r : r + 1]
    disc = xx**2 + yy**2 <= r * r
    wide = ndimage.binary_opening(unseen, structure=disc)
    labels, n = ndimage.label(wide, structure=np.ones((3, 3), bool))
    if n == 0:
        return []
    keep = np.arange(1, n + 1)
    counts = np.asarray(ndimage.sum_labels(wide, labels, keep))
    centres = ndimage.center_of_mass(wide, labels, keep)
    out = []
    for count, (cy, cx) in zip(counts, centres, strict=True):
        area = float(count) * resolution * resolution
        if area >= min_area:
            x = float(origin[0] + (cx + 0.5) * resolution)
            out.append(UnseenRegion(area, (x, float(origin[1] + (cy + 0.5) * resolution))))
    return sorted(out, key=lambda u: -u.area_m2)
