"""Global costmap from the SLAM map and local costmap from the latest scans (costmap_2d-like)."""

from __future__ import annotations

import math

import numpy as np

from worker.explore import costmap_kernels as ck
from worker.explore import local_kernels as lk
from worker.explore.params import CostmapParams, DwaParams

_TILE = 8  # [cells] block size of the inflation updates


class GlobalCostmap:
    """Static layer (SLAM map) + inflation layer, updated only where the map changed.

    Grids are `[iy, ix]`, row 0 at the bottom, in the SLAM map's frame: `lethal (H, W) bool`,
    `unknown (H, W) bool`, `inflated (H, W) uint8` (costmap_2d values from obstacles only; the
    master value of an unknown cell is NO_INFORMATION unless an obstacle is within the
    inscribed radius, as costmap_2d's inflation layer writes it).
    """

    def __init__(self, params: CostmapParams, keep_map_obstacles: bool = False):
        """keep_map_obstacles: keep the SLAM map's obstacles apart (`map_lethal`), for the
        door passage (DoorParams.door_align)."""
        self.params = params
        self.keep_map_obstacles = keep_map_obstacles
        self.inscribed_radius = params.footprint_half_m
        self.circumscribed_radius = params.footprint_half_m * math.sqrt(2.0)
        self.resolution = 0.0
        self.origin = np.zeros(2)
        self.frame_id = 0  # changes whenever the grid is reallocated (users resize with it)
        self.lethal = np.zeros((0, 0), dtype=np.bool_)
        self.unknown = np.zeros((0, 0), dtype=np.bool_)
        self.inflated = np.zeros((0, 0), dtype=np.uint8)
        # obstacle layer: the laser's hits, kept until a beam passes through (raytrace_scan)
        self.obstacle = np.zeros((0, 0), dtype=np.bool_)
        # the SLAM map's obstacles alone (above occupied_thresh), without the obstacle
        # layer's: kept only for the door passage (explore.doors.door_align), else empty
        self.map_lethal = np.zeros((0, 0), dtype=np.bool_)
        self._kernel = np.zeros((1, 1), dtype=np.uint8)
        self._fresh = np.zeros((0, 0), dtype=np.bool_)  # new obstacle cells to stamp
        self._tiles = np.zeros((0, 0), dtype=np.bool_)  # blocks obstacles went from
        self._fresh_tiles = np.zeros((0, 0), dtype=np.bool_)  # blocks with fresh cells

    @property
    def shape(self) -> tuple[int, int]:
        return self.lethal.shape

    @property
    def map_obstacles(self) -> np.ndarray:
        """The SLAM map's obstacles alone where they are kept (`map_lethal`, the door
        passage on), else `lethal` (a noise-free laser's marks are where the map's are)."""
        return self.map_lethal if self.map_lethal.shape == self.lethal.shape else self.lethal

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        """(ix, iy) of the cell holding world point (x, y), possibly outside the grid."""
        return (
            int(math.floor((x - self.origin[0]) / self.resolution)),
            int(math.floor((y - self.origin[1]) / self.resolution)),
        )

    def cell_to_world(self, ix, iy):
        """Centre of cell (ix, iy) in metres (works on arrays too)."""
        return (
            self.origin[0] + (np.asarray(ix) + 0.5) * self.resolution,
            self.origin[1] + (np.asarray(iy) + 0.5) * self.resolution,
        )

    def in_bounds(self, ix: int, iy: int) -> bool:
        h, w = self.shape
        return 0 <= ix < w and 0 <= iy < h

    def master(self) -> np.ndarray:
        """(H, W) uint8 combined costs: inflation, and NO_INFORMATION for unknown cells."""
        out = self.inflated.copy()
        out[self.unknown & (self.inflated < ck.INSCRIBED)] = ck.NO_INFORMATION
        return out

    def update(self, prob: np.ndarray, resolution: float, origin, window_m=None, scan=None):
        """Bring the layers up to date with the SLAM map `prob (h, w)` (NaN unknown).

        The SLAM map may be cropped and grow between calls: the costmap keeps its own frame,
        enlarged by `growth_margin` whenever the map leaves it (old layers are copied, not
        recomputed). window_m: `(x0, y0, x1, y1)` [m] where the map can have changed since the
        last call (None: everywhere). Returns the bounding box `(y0, y1, x0, x1)` of the cells
        whose lethal or unknown state changed (empty when y1 == y0), in the costmap's frame.
        scan: `(pose (3,), ranges (B,), angles (B,), range_max)` in the map frame, for the
        obstacle layer (None: the layer is left as it is).
        """
        origin = np.asarray(origin, dtype=float)[:2]
        ph, pw = prob.shape
        if float(resolution) != self.resolution:
            self._reset(resolution, origin, (ph, pw))
            window_m = None
        off_x = int(round((origin[0] - self.origin[0]) / self.resolution))
        off_y = int(round((origin[1] - self.origin[1]) / self.resolution))
        h, w = self.shape
        if off_x < 0 or off_y < 0 or off_x + pw > w or off_y + ph > h:
            self._grow(off_y, off_x, ph, pw)
            off_x = int(round((origin[0] - self.origin[0]) / self.resolution))
            off_y = int(round((origin[1] - self.origin[1]) / self.resolution))
            h, w = self.shape
        marked = self._mark(scan)
        if window_m is None:
            y0, y1, x0, x1 = 0, h, 0, w
        else:
            x0, y0 = self.world_to_cell(window_m[0], window_m[1])
            x1, y1 = self.world_to_cell(window_m[2], window_m[3])
            y0, y1, x0, x1 = max(0, y0), min(h, y1 + 1), max(0, x0), min(w, x1 + 1)
            y0, y1, x0, x1 = _union((y0, y1, x0, x1), marked)
        if y1 <= y0 or x1 <= x0:
            return (0, 0, 0, 0)
        if self.keep_map_obstacles:
            self._classify_map(prob, off_y, off_x, y0, y1, x0, x1)
        t = _TILE
        tiles, fresh_tiles = self._tile_flags()
        ly0, ly1, lx0, lx1, uy0, uy1, ux0, ux1 = ck.classify_region(
            prob, off_y, off_x, self.params.occupied_thresh, self.lethal, self.unknown,
            y0, y1, x0, x1, tiles, self._fresh, fresh_tiles, t, self.obstacle,
            self.params.obstacle_min_prob,
        )  # fmt: skip
        if ly1 > ly0:
            # obstacles that went away: their blocks are recomputed; new ones: stamped in
            # (both look at the window's blocks only, and clear the flags they find)
            box = (ly0 // t, (ly1 + t - 1) // t, lx0 // t, (lx1 + t - 1) // t)
            ck.inflate_tiles(self.lethal, self._kernel, self.inflated, tiles, t, *box)
            ck.stamp_fresh(
                self.lethal, self._kernel, self.inflated, self._fresh, fresh_tiles, t, *box
            )
        return _union((ly0, ly1, lx0, lx1), (uy0, uy1, ux0, ux1))

    def _tile_flags(self) -> tuple[np.ndarray, np.ndarray]:
        """The block flags of the inflation updates (kept all clear between updates, so that
        an update costs its window, not the map) and the fresh-obstacle layer, sized to the
        grid."""
        h, w = self.shape
        t = _TILE
        shape = ((h + t - 1) // t, (w + t - 1) // t)
        if self._tiles.shape != shape:
            self._tiles = np.zeros(shape, dtype=np.bool_)
            self._fresh_tiles = np.zeros(shape, dtype=np.bool_)
        if self._fresh.shape != self.lethal.shape:
            self._fresh = np.zeros(self.lethal.shape, dtype=np.bool_)
        return self._tiles, self._fresh_tiles

    def _classify_map(self, prob, off_y: int, off_x: int, y0: int, y1: int, x0: int, x1: int):
        """map_lethal in the window `[y0, y1) x [x0, x1)`: the map's cells above
        occupied_thresh (cells outside the map: not obstacles)."""
        if self.map_lethal.shape != self.lethal.shape:
            self.map_lethal = np.zeros(self.lethal.shape, dtype=np.bool_)
            y0, y1, x0, x1 = 0, self.lethal.shape[0], 0, self.lethal.shape[1]
        ph, pw = prob.shape
        win = self.map_lethal[y0:y1, x0:x1]
        win[:] = False
        sy0, sy1 = max(y0 - off_y, 0), min(y1 - off_y, ph)
        sx0, sx1 = max(x0 - off_x, 0), min(x1 - off_x, pw)
        if sy1 > sy0 and sx1 > sx0:
            with np.errstate(invalid="ignore"):
                part = prob[sy0:sy1, sx0:sx1] > self.params.occupied_thresh
            win[sy0 + off_y - y0 : sy1 + off_y - y0, sx0 + off_x - x0 : sx1 + off_x - x0] = part

    def _mark(self, scan) -> tuple[int, int, int, int]:
        """Clear and mark the obstacle layer with one scan; the box of the cells changed."""
        if scan is None:
            return (0, 0, 0, 0)
        pose, ranges, angles, range_max = scan
        p = self.params
        return ck.raytrace_scan(
            self.obstacle, float(self.origin[0]), float(self.origin[1]), self.resolution,
            float(pose[0]), float(pose[1]), float(pose[2]), np.asarray(ranges, dtype=float),
            np.asarray(angles, dtype=float), float(range_max), p.obstacle_range, p.raytrace_range,
        )  # fmt: skip

    def _reset(self, resolution: float, origin: np.ndarray, shape) -> None:
        self.resolution = float(resolution)
        self.origin = origin.copy()
        self.frame_id += 1
        self.lethal = np.zeros(shape, dtype=np.bool_)
        self.unknown = np.ones(shape, dtype=np.bool_)
        self.inflated = np.zeros(shape, dtype=np.uint8)
        self.obstacle = np.zeros(shape, dtype=np.bool_)
        p = self.params
        self._kernel = ck.inflation_kernel(
            self.resolution, self.inscribed_radius, p.cost_scaling_factor, p.inflation_radius
        )

    def _grow(self, off_y: int, off_x: int, ph: int, pw: int) -> None:
        """Enlarge the frame to hold the incoming map plus a margin, keeping the old layers."""
        h, w = self.shape
        m = int(math.ceil(self.params.growth_margin / self.resolution))
        ny0 = min(0, off_y - m) if off_y < 0 else 0
        nx0 = min(0, off_x - m) if off_x < 0 else 0
        ny1 = max(h, off_y + ph + m) if off_y + ph > h else h
        nx1 = max(w, off_x + pw + m) if off_x + pw > w else w
        shape = (ny1 - ny0, nx1 - nx0)
        lethal = np.zeros(shape, dtype=np.bool_)
        unknown = np.ones(shape, dtype=np.bool_)
        inflated = np.zeros(shape, dtype=np.uint8)
        lethal[-ny0 : -ny0 + h, -nx0 : -nx0 + w] = self.lethal
        unknown[-ny0 : -ny0 + h, -nx0 : -nx0 + w] = self.unknown
        inflated[-ny0 : -ny0 + h, -nx0 : -nx0 + w] = self.inflated
        obstacle = np.zeros(shape, dtype=np.bool_)
        obstacle[-ny0 : -ny0 + h, -nx0 : -nx0 + w] = self.obstacle
        self.lethal, self.unknown, self.inflated = lethal, unknown, inflated
        self.obstacle = obstacle
        self.origin = self.origin + np.array([nx0, ny0]) * self.resolution
        self.frame_id += 1
        # Old obstacles near the old border inflate into the new ring around it.
        r = self._kernel.shape[0] // 2
        H, W = shape
        oy0, oy1, ox0, ox1 = -ny0, -ny0 + h, -nx0, -nx0 + w
        ry0, ry1, rx0, rx1 = max(0, oy0 - r), min(H, oy1 + r), max(0, ox0 - r), min(W, ox1 + r)
        for y0, y1, x0, x1 in (
            (ry0, oy0, rx0, rx1), (oy1, ry1, rx0, rx1), (oy0, oy1, rx0, ox0), (oy0, oy1, ox1, rx1)
        ):  # fmt: skip
            if y1 > y0 and x1 > x0:
                ck.inflate_region(self.lethal, self._kernel, self.inflated, y0, y1, x0, x1)


def _union(a, b):
    """Union of two `(y0, y1, x0, x1)` boxes, either possibly empty."""
    if a[1] <= a[0]:
        return tuple(b)
    if b[1] <= b[0]:
        return tuple(a)
    return (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]))


_NO_WINDOW = np.zeros((0, 0), dtype=np.bool_)  # a scan that clears no mark


class LocalCostmap:
    """Rolling window around the robot: the recent scans' obstacles over the SLAM map's.

    Aligned with the global grid (same resolution, cell edges on the same lattice) so that
    the DWA scores trajectories against it directly. ROS's local costmap held scan obstacles
    only; ours adds the map's obstacles, so that walls in the laser's blind 90 degrees behind
    the robot still count when it turns. Arrays `(n, n)`, `[iy, ix]`: `lethal`, `near`,
    `inner` bool (see local_kernels.local_layers) and `cost` uint8.
    """

    def __init__(self, params: CostmapParams, dwa: DwaParams, resolution: float):
        """dwa: the local planner's limits, which set how far its trajectories reach."""
        self.params = params
        self.resolution = float(resolution)
        self.n = int(math.ceil(params.local_window_m / self.resolution))
        res_m = self.resolution
        half = (params.footprint_half_m + params.footprint_padding) / res_m
        # A footprint corner reaches half*sqrt(2) from the centre, and both the robot and the
        # obstacle may sit anywhere in their cells: centre cells up to (half + 1) sqrt(2) apart.
        self._near = lk.disc_half_widths((half + 1.0) * math.sqrt(2.0) + 0.01)
        self._inner = lk.disc_half_widths(half)
        # farthest a trajectory takes the footprint from the robot: the map's obstacles
        # matter for the collision test only that near
        reach_m = dwa.max_vel_x * dwa.sim_time + dwa.heading_lookahead + 2 * half * res_m
        self._reach = int(math.ceil(reach_m / self.resolution)) + 2
        # the obstacle marks, in the order added: (K, 2) points [m], the time each was seen
        # and the number of the scan (add_points call) that made it
        self._pts = np.zeros((0, 2))
        self._t = np.zeros(0)
        self._scan = np.zeros(0, dtype=np.int64)
        self._n_scans = 0
        self._lattice = np.zeros(2)  # a corner of the global grid's cells (set by build)
        self.origin = np.zeros(2)
        shape = (self.n, self.n)
        self.lethal = np.zeros(shape, dtype=np.bool_)
        self.near = np.zeros(shape, dtype=np.bool_)
        self.inner = np.zeros(shape, dtype=np.bool_)
        self.cost = np.zeros(shape, dtype=np.uint8)

    def add_scan(
        self, t: float, pose: np.ndarray, ranges_m: np.ndarray, angles: np.ndarray, range_max: float
    ) -> None:
        """Mark the hits (readings < range_max) seen from `pose (3,) [x, y, theta]`."""
        hit = ranges_m < range_max * 0.999
        if self.params.local_raytrace and len(self._pts):
            self._drop(t, *self._crossed(pose, ranges_m, angles, range_max))
        else:
            self._drop(t)
        # a reading ends on the obstacle's face: nudge it inside, so that rounding cannot
        # put the mark in the free cell in front
        r = ranges_m[hit] + 0.2 * self.resolution
        a = angles[hit] + pose[2]
        self._append(t, np.column_stack((pose[0] + r * np.cos(a), pose[1] + r * np.sin(a))))

    def _crossed(self, pose, ranges_m, angles, range_max) -> tuple[np.ndarray, float, float]:
        """The cells the beams of this scan cross (their marks go: costmap_2d's raytrace
        clearing) in a window of the local costmap's size around the robot, on the lattice
        `build` rasterises on (so a mark is cleared exactly when its cell is): `(n, n) bool`
        and the window's lower-left corner [m]."""
        res, n = self.resolution, self.n
        ox = self._lattice[0] + (math.floor((pose[0] - self._lattice[0]) / res) - n // 2) * res
        oy = self._lattice[1] + (math.floor((pose[1] - self._lattice[1]) / res) - n // 2) * res
        crossed = lk.crossed_cells(
            ox, oy, res, n, float(pose[0]), float(pose[1]), float(pose[2]),
            np.asarray(ranges_m, dtype=float), np.asarray(angles, dtype=float), float(range_max),
        )  # fmt: skip
        return crossed, ox, oy

    def add_points(self, t: float, pts: np.ndarray) -> None:
        """Mark obstacle points `(K, 2) [x, y]` (map frame) observed at time t."""
        self._drop(t)
        self._append(t, np.asarray(pts, dtype=float).reshape(-1, 2))

    def _drop(
        self, t: float, crossed: np.ndarray = _NO_WINDOW, ox: float = 0.0, oy: float = 0.0
    ) -> None:
        """Drop the marks expired at time t and those in the cells of `crossed` (the window
        of `_crossed` with lower-left corner (ox, oy); by default none)."""
        self._pts, self._t, self._scan = lk.kept_marks(
            self._pts, self._t, self._scan, t - self.params.local_persistence, crossed, ox, oy,
            self.resolution,
        )  # fmt: skip

    def _append(self, t: float, pts: np.ndarray) -> None:
        """Add the marks `(K, 2)` of one scan at time t (the expired ones already gone;
        local_persistence is positive, so these are not)."""
        self._n_scans += 1
        self._pts = np.concatenate((self._pts, pts))
        self._t = np.concatenate((self._t, np.full(len(pts), float(t))))
        self._scan = np.concatenate((self._scan, np.full(len(pts), self._n_scans)))

    def clear(self) -> None:
        """Recovery behaviour: forget all but the newest scan's obstacles."""
        keep = self._scan == self._n_scans
        self._pts, self._t, self._scan = self._pts[keep], self._t[keep], self._scan[keep]

    def build(
        self,
        x: float,
        y: float,
        costmap: GlobalCostmap | None = None,
        theta: float | None = None,
        use_map: bool = True,
        clear_touching: bool = False,
        map_only: bool = False,
    ) -> None:
        """Rasterise the window centred on (x, y): scan obstacles, then the map's (if given);
        with the robot's heading theta, the cells under its footprint are cleared (see
        local_kernels.local_layers; clear_touching: the scan cells it touches too). use_map
        False: the map's obstacles are left out (the thesis's scan-only local costmap);
        map_only: the SLAM map's obstacles alone (`GlobalCostmap.map_obstacles`), no scans."""
        res = self.resolution
        half = self.n // 2
        g_origin = costmap.origin if costmap is not None else np.zeros(2)
        ix = math.floor((x - g_origin[0]) / res)
        iy = math.floor((y - g_origin[1]) / res)
        self.origin = np.array([g_origin[0] + (ix - half) * res, g_origin[1] + (iy - half) * res])
        self._lattice = np.asarray(g_origin, dtype=float).copy()
        pts = np.zeros((0, 2)) if map_only else self._pts
        if costmap is None or costmap.shape[0] == 0 or not use_map:
            g_lethal, g_cost = np.zeros((1, 1), np.bool_), np.zeros((1, 1), np.uint8)
            g_oy = g_ox = -(10**6)
        else:
            g_lethal = costmap.map_obstacles if map_only else costmap.lethal
            g_cost = costmap.inflated
            g_oy, g_ox = iy - half, ix - half
        self.lethal, self.near, self.inner, self.cost = lk.local_layers(
            np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]),
            float(self.origin[0]), float(self.origin[1]), res, self.n,
            self._near, self._inner, g_lethal, g_cost, int(g_oy), int(g_ox), self._reach,
            float(x), float(y), float(theta or 0.0),
            self.params.footprint_half_m if theta is not None else -1.0, clear_touching,
        )  # fmt: skip


def cost_from_distance(
    dist_m: np.ndarray, inscribed_radius: float, cost_scaling_factor: float, inflation_radius: float
) -> np.ndarray:
    """Vectorised costmap_2d computeCost on a distance field `(H, W)` [m] -> `(H, W) uint8`."""
    with np.errstate(over="ignore", invalid="ignore"):
        c = np.floor(
            (ck.INSCRIBED - 1) * np.exp(-cost_scaling_factor * (dist_m - inscribed_radius))
        )
    c = np.where(dist_m > inflation_radius, 0.0, c)
    c = np.where(dist_m <= inscribed_radius, ck.INSCRIBED, c)
    c = np.where(dist_m == 0.0, ck.LETHAL, c)
    return c.astype(np.uint8)
