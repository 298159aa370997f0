"""navfn-like global planner: Dijkstra on the costmap, path from the robot to a goal cell."""

from __future__ import annotations

import dataclasses
import math
from contextlib import contextmanager

import numpy as np

from worker.explore import planner_kernels as pk
from worker.explore.costmap import GlobalCostmap
from worker.explore.params import CostmapParams, PlannerParams


class DijkstraSearch:
    """Reusable Dijkstra buffers sized to the costmap (valid cells are marked by a run stamp)."""

    def __init__(self):
        # stamp (H, W) int32: cells visited by the pass whose id is run_id (`new_stamp`);
        # parent (H, W) uint8: the step that reached each cell (planner_kernels.dijkstra)
        self.shape = (0, 0)
        self.run_id = 0
        self.potential = np.zeros((0, 0))
        self.parent = np.zeros((0, 0), dtype=np.uint8)
        self.stamp = np.zeros((0, 0), dtype=np.int32)
        self.queue = np.zeros(0, dtype=np.int64)

    def run(
        self,
        costmap: GlobalCostmap,
        start_cell: tuple[int, int],
        target: np.ndarray,
        params: PlannerParams,
        stop_extra: float = 0.0,
        allow_unknown: bool | None = None,
        goal_cell: tuple[int, int] | None = None,
        escape_m: float | None = None,
    ) -> np.ndarray:
        """Search from `start_cell (ix, iy)`; settled target flat indices, nearest first.
        escape_m: the escape radius [m] (default params.escape_radius); a wider one lets the
        plan cross cells under the margin that far, inscribed cells only within
        params.escape_radius."""
        self._fit(costmap.shape)
        self.run_id += 1
        allow = params.allow_unknown if allow_unknown is None else allow_unknown
        escape = params.escape_radius if escape_m is None else escape_m  # [m]
        return pk.dijkstra(
            costmap.inflated,
            costmap.unknown,
            start_cell[1],
            start_cell[0],
            target,
            float(stop_extra),
            params.neutral_cost,
            params.cost_factor,
            allow,
            self.potential,
            self.parent,
            self.stamp,
            self.run_id,
            -1 if goal_cell is None else goal_cell[1],
            -1 if goal_cell is None else goal_cell[0],
            planner_blocked_cost(params, costmap.params),
            int(round(escape / costmap.resolution)),
            int(round(min(escape, params.escape_radius) / costmap.resolution)),
        )

    def _fit(self, shape: tuple[int, int]) -> None:
        """Buffers of `shape` (new ones, all stamps 0, when the costmap's shape changed)."""
        if shape != self.shape:
            self.shape = shape
            self.potential = np.zeros(shape)
            self.parent = np.zeros(shape, dtype=np.uint8)
            self.stamp = np.zeros(shape, dtype=np.int32)
            self.run_id = 0

    def new_stamp(self, shape: tuple[int, int]) -> int:
        """An id no cell of `stamp` holds yet, for a pass of another search over the same
        grid (the frontier clusters, the unknown regions' flood) that marks the cells it
        visited in `stamp`: one stamp buffer for all of a run's searches, each pass telling
        its own marks by its id."""
        self._fit(shape)
        self.run_id += 1
        return self.run_id

    def sealed_off(
        self,
        costmap: GlobalCostmap,
        start_cell: tuple[int, int],
        goal_cell: tuple[int, int],
        params: PlannerParams,
        escape_m: float | None = None,
    ) -> bool:
        """True when `run` from start_cell could not reach goal_cell (a goal walled into a
        pocket of at most params.sealed_pocket_cells): proven on the goal's side, without the
        search of everything reachable that `run` makes before it gives up."""
        if costmap.shape != self.shape:
            return False  # buffers are sized by `run`
        self.run_id += 1
        budget = params.sealed_pocket_cells
        if self.queue.shape[0] < budget:
            self.queue = np.empty(budget, dtype=np.int64)
        escape = params.escape_radius if escape_m is None else escape_m  # [m]
        return bool(
            pk.sealed_off(
                costmap.inflated, costmap.unknown, goal_cell[1], goal_cell[0], start_cell[1],
                start_cell[0], params.allow_unknown, planner_blocked_cost(params, costmap.params),
                int(round(escape / costmap.resolution)), budget, self.stamp,
                self.run_id, self.queue,
            )
        )  # fmt: skip

    def potential_at(self, flat_idx: np.ndarray) -> np.ndarray:
        """Potentials of settled cells given as flat indices."""
        return self.potential.reshape(-1)[flat_idx]

    def path_to(self, flat_idx: int) -> np.ndarray:
        """`(K, 2) int64 [iy, ix]` cells from the search start to a settled cell."""
        return pk.trace_path(self.parent, int(flat_idx), self.shape[1])


class GlobalPlanner:
    """Plans on the global costmap with navfn's cost model, from the robot to one goal cell."""

    def __init__(
        self,
        params: PlannerParams,
        closed: ClosedGaps | None = None,
        search: DijkstraSearch | None = None,
    ):
        """search: the Dijkstra buffers to plan in (shared with the frontier search, so a
        run keeps one set of map-sized buffers; each reads its results right after its own
        search); a new one when None."""
        self.params = params
        self.closed = closed if closed is not None else ClosedGaps()
        self.search = search if search is not None else DijkstraSearch()
        self._target = np.zeros((0, 0), dtype=np.bool_)
        # plans of this map state by question (`map_changed`); None: not kept (nobody tells
        # the planner when the costmap changes)
        self._plans: dict[tuple, np.ndarray | None] | None = None

    def map_changed(self) -> None:
        """The costmap's lethal or unknown cells (so its costs) may have changed: forget the
        plans kept. The first call turns the keeping on: from then on the owner calls it after
        every change, and a plan asked again on the same map state (the robot still in its
        cell: planning failed and is retried every control period, or the robot turns in
        place) is the one planned before, without a search."""
        self._plans = {}

    def plan(
        self, costmap: GlobalCostmap, start_xy, goal_xy, squeeze: bool = False
    ) -> np.ndarray | None:
        """Path `(K, 2) [x, y]` (cell centres, map frame) from the robot to the goal, or None.
        squeeze: a goal of the last pass, which may be planned with squeeze_margin. A pure
        function of the costmap, the start and goal cells, squeeze and the closed gaps: kept
        for the same question until `map_changed`."""
        sx, sy = costmap.world_to_cell(start_xy[0], start_xy[1])
        gx, gy = costmap.world_to_cell(goal_xy[0], goal_xy[1])
        if self._plans is None:
            return self._plan_cells(costmap, sx, sy, gx, gy, squeeze)
        key = (
            costmap.frame_id, costmap.shape, sx, sy, gx, gy, bool(squeeze),
            self.closed.points.tobytes(),
        )  # fmt: skip
        if key not in self._plans:
            if len(self._plans) >= 16:
                self._plans.clear()
            self._plans[key] = self._plan_cells(costmap, sx, sy, gx, gy, squeeze)
        return self._plans[key]

    def _plan_cells(
        self, costmap: GlobalCostmap, sx: int, sy: int, gx: int, gy: int, squeeze: bool
    ) -> np.ndarray | None:
        """`plan` from cell (sx, sy) to cell (gx, gy)."""
        if not (costmap.in_bounds(sx, sy) and costmap.in_bounds(gx, gy)):
            return None
        if self._target.shape != costmap.shape:
            self._target = np.zeros(costmap.shape, dtype=np.bool_)
        self._target[gy, gx] = True
        search, p = self.search, self.params

        def attempt(escape_m: float | None = None) -> np.ndarray:
            # a goal the map walled in is found out on its side (the search would first
            # cover everything reachable); the plans are the same
            if search.sealed_off(costmap, (sx, sy), (gx, gy), p, escape_m=escape_m):
                return np.zeros(0, dtype=np.int64)
            return search.run(
                costmap, (sx, sy), self._target, p, goal_cell=(gx, gy), escape_m=escape_m
            )

        try:
            # a gap closed after a failure stays closed to every attempt: the escapes near the
            # robot would otherwise send it back through the gap it just backed out of
            with self.closed.applied(costmap):
                found = attempt()
                if found.size == 0:  # a pocket the map sealed around the robot: wider escape
                    found = attempt(p.pocket_escape_radius)
                if found.size == 0 and p.planner_margin > p.narrow_margin:
                    # a door narrower than the margin allows
                    p = narrow_params(p)
                    found = attempt()
                if found.size == 0 and squeeze and p.narrow_margin > p.squeeze_margin:
                    # the last pass: navfn's own rule (any cell below the inscribed cost), as
                    # move_base would plan through it
                    p = narrow_params(p, squeeze=True)
                    found = attempt()
        finally:
            self._target[gy, gx] = False
        if found.size == 0:
            return None
        cells = self.search.path_to(found[0])
        xs, ys = costmap.cell_to_world(cells[:, 1], cells[:, 0])
        return np.column_stack((xs, ys))


class ClosedGaps:
    """Gaps under the planner's margin the robot failed to get through (a goal given up
    with its plan through one near the robot): closed to every plan and goal search (the
    narrow fallback, which plans through any cell below the inscribed cost, and the escapes
    near the robot, which cross cells under the margin), so that they do not send the robot
    back to them goal after goal. Kept as points (map frame); `clear` opens them all again.
    A robot standing in a closed cell can still leave: escaping from a cell at or above the
    planner's blocked cost enters inscribed cells near it (planner_kernels.dijkstra)."""

    def __init__(self):
        self.points = np.zeros((0, 2))

    def clear(self) -> None:
        self.points = np.zeros((0, 2))

    def close(self, costmap, params: PlannerParams, path_xy, robot_xy, radius: float) -> int:
        """Close the gap of `path_xy (K, 2)` within `radius` [m] of the robot: its cells that
        only the narrow fallback or an escape lets a plan through (cost at or above the
        margin's blocked cost, below INSCRIBED), and the gap's other such cells within the
        margin's clearance (footprint half side + planner margin) of them, so that the next
        plan does not slip through the same door a line beside this one. Returns how many
        of the path's cells were closed."""
        from worker.explore.costmap_kernels import INSCRIBED

        if path_xy is None or len(path_xy) == 0:
            return 0
        pts = np.asarray(path_xy, dtype=float)
        near = np.hypot(pts[:, 0] - robot_xy[0], pts[:, 1] - robot_xy[1]) <= radius
        ix, iy = self._cells(costmap, pts[near])
        if ix.size == 0:
            return 0
        blocked = planner_blocked_cost(params, costmap.params)
        c = costmap.inflated[iy, ix]
        narrow = (c >= blocked) & (c < INSCRIBED)
        if not narrow.any():
            return 0
        half = costmap.params.footprint_half_m
        disc = cells_in_radius(half + params.planner_margin, costmap.resolution)
        h, w = costmap.shape
        gy = (iy[narrow][:, None] + disc[:, 0]).ravel()
        gx = (ix[narrow][:, None] + disc[:, 1]).ravel()
        ok = (gy >= 0) & (gy < h) & (gx >= 0) & (gx < w)
        gy, gx = gy[ok], gx[ok]
        cg = costmap.inflated[gy, gx]
        gap = (cg >= blocked) & (cg < INSCRIBED)
        cells = np.unique(gy[gap] * w + gx[gap])
        xs, ys = costmap.cell_to_world(cells % w, cells // w)
        self.points = np.concatenate([self.points, np.column_stack((xs, ys))])
        return int(np.count_nonzero(narrow))

    @staticmethod
    def _cells(costmap, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """In-bounds cells `(ix, iy)` of points `(K, 2)`."""
        ix = np.floor((pts[:, 0] - costmap.origin[0]) / costmap.resolution).astype(np.int64)
        iy = np.floor((pts[:, 1] - costmap.origin[1]) / costmap.resolution).astype(np.int64)
        h, w = costmap.shape
        ok = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        return ix[ok], iy[ok]

    @contextmanager
    def applied(self, costmap):
        """While inside: the closed cells and their 8 neighbours at INSCRIBED in the costmap
        (a one-cell gap must not open beside a closed cell); restored after."""
        from worker.explore.costmap_kernels import INSCRIBED

        if len(self.points) == 0:
            yield
            return
        ix, iy = self._cells(costmap, self.points)
        h, w = costmap.shape
        dx, dy = np.meshgrid(np.arange(-1, 2), np.arange(-1, 2))
        ix = np.clip((ix[:, None] + dx.ravel()).ravel(), 0, w - 1)
        iy = np.clip((iy[:, None] + dy.ravel()).ravel(), 0, h - 1)
        saved = costmap.inflated[iy, ix].copy()
        costmap.inflated[iy, ix] = np.maximum(saved, INSCRIBED)
        try:
            yield
        finally:
            costmap.inflated[iy, ix] = saved


def narrow_params(params: PlannerParams, squeeze: bool = False) -> PlannerParams:
    """The settings with planner_margin lowered to narrow_margin (the fallback that lets the
    plans through doors whose clearance is under the margin), or with `squeeze` to
    squeeze_margin (the last pass's: down to the inscribed radius)."""
    margin = params.squeeze_margin if squeeze else params.narrow_margin
    return dataclasses.replace(params, planner_margin=margin)


def planner_blocked_cost(params: PlannerParams, costmap: CostmapParams) -> int:
    """Costmap value from which the planners treat a cell as blocked: the inflation cost at
    the inscribed radius (the footprint's half side) plus `planner_margin` (INSCRIBED when
    the margin is 0)."""
    from worker.explore.costmap_kernels import INSCRIBED, inflation_cost

    if params.planner_margin <= 0:
        return INSCRIBED
    half = costmap.footprint_half_m
    d = half + params.planner_margin
    return inflation_cost(d, half, costmap.cost_scaling_factor, 1e9) + 1


def path_length(path_xy: np.ndarray) -> float:
    """Length [m] of a polyline `(K, 2)`."""
    if path_xy is None or len(path_xy) < 2:
        return 0.0
    return float(np.sum(np.hypot(*np.diff(path_xy, axis=0).T)))


def remaining_length(path_xy: np.ndarray | None, xy) -> float:
    """Length [m] of the rest of a polyline `(K, 2)` from `xy`: to its vertex nearest `xy`,
    then along it to its end (inf for no path)."""
    if path_xy is None or len(path_xy) == 0:
        return math.inf
    d = np.hypot(path_xy[:, 0] - xy[0], path_xy[:, 1] - xy[1])
    i0 = int(np.argmin(d))
    return float(d[i0]) + path_length(path_xy[i0:])


def cells_in_radius(radius_m: float, resolution: float) -> np.ndarray:
    """Offsets `(K, 2) int64 [dy, dx]` of the cells whose centres lie within `radius_m`."""
    r = int(math.ceil(radius_m / resolution))
    dy, dx = np.mgrid[-r : r + 1, -r : r + 1]
    keep = np.hypot(dx, dy) * resolution <= radius_m
    return np.column_stack((dy[keep], dx[keep])).astype(np.int64)
