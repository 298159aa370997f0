"""Frontier search (explore_lite-like): clusters of free cells by unknown, nearest by travel."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from worker.explore import frontier_kernels as fk
from worker.explore.costmap import GlobalCostmap
from worker.explore.costmap_kernels import INSCRIBED
from worker.explore.frontier_memo import ChoiceMemo
from worker.explore.params import FrontierParams, PlannerParams
from worker.explore.planner import (
    ClosedGaps,
    DijkstraSearch,
    cells_in_radius,
    narrow_params,
    planner_blocked_cost,
)

_TILE = 16  # [cells] block size of the frontier cell counts


@dataclass(frozen=True)
class FrontierGoal:
    """A chosen exploration goal (map frame)."""

    goal_xy: np.ndarray  # (2,) [m] where to drive: a low-cost cell near the frontier
    yaw: float  # [rad] heading at the goal: looking at the frontier
    frontier_xy: np.ndarray  # (2,) [m] the frontier cell nearest to the goal
    cluster_size_m: float  # [m] frontier length (cells x resolution, as explore_lite)
    travel_cost: float  # [-] navfn potential from the robot to the goal
    n_clusters: int  # clusters big enough at the time of the choice
    # (K, 2) [x, y] the search's own path from the robot to the goal, through known space
    # (a first plan for free), or None
    path_xy: np.ndarray | None = None
    look_through: bool = False  # a goal of the look-through pass (FrontierSearch.choose)
    squeeze: bool = False  # a goal of the last pass, through a gap under narrow_margin


class FrontierSearch:
    """Keeps the frontier mask up to date and picks the nearest frontier cluster by travel cost."""

    def __init__(
        self,
        params: FrontierParams,
        planner: PlannerParams,
        closed: ClosedGaps | None = None,
        search: DijkstraSearch | None = None,
    ):
        """planner: the goal search's cost model and margins; search: the Dijkstra buffers of
        the goal search (see GlobalPlanner); new if None."""
        self.params = params
        self.planner = planner
        self.closed = closed if closed is not None else ClosedGaps()  # the narrow search's
        # the look-through pass's goal search: goals up to look_through_radius from the
        # frontier, one such radius of travel past the first candidate
        self._look_params = dataclasses.replace(
            params, goal_radius=max(params.look_through_radius, 1e-9), goal_search_extra=1.0
        )
        self.frontier = np.zeros((0, 0), dtype=np.bool_)
        self.n_frontier_cells = 0
        self.search = search if search is not None else DijkstraSearch()
        self._target = np.zeros((0, 0), dtype=np.bool_)
        # (H, W) int32: the cluster of each goal candidate (`_search`), and before that the
        # labelling's scratch (`clusters`); the passes' visited marks are the Dijkstra
        # buffers' stamps (`DijkstraSearch.new_stamp`)
        self._owner = np.zeros((0, 0), dtype=np.int32)
        self._unk_state = np.zeros((0, 0), dtype=np.int8)
        self.seen = np.zeros((0, 0), dtype=np.uint8)  # close looks at each frontier cell
        self._seen_origin = np.zeros(2)
        self._unk_id = 0  # the stamp id of the unknown regions' flood (`open_cells`)
        self._frame_id = -1
        # frontier cells per _TILE x _TILE block: the clusters are read from the blocks
        # that hold some, not map-wide
        self._counts = np.zeros((0, 0), dtype=np.int32)
        # the answers of `choose` while nothing it reads changes (a robot with nothing left
        # to explore asks every control period)
        self.memo = ChoiceMemo()

    def update(self, costmap: GlobalCostmap, bbox) -> None:
        """Refresh the frontier cells in `bbox (y0, y1, x0, x1)` grown by one cell (None: all)."""
        h, w = costmap.shape
        if self.frontier.shape != (h, w) or costmap.frame_id != self._frame_id:
            self.frontier = np.zeros((h, w), dtype=np.bool_)
            self._target = np.zeros((h, w), dtype=np.bool_)
            self._owner = np.zeros((h, w), dtype=np.int32)
            self._unk_state = np.zeros((h, w), dtype=np.int8)
            self._carry_seen(costmap)
            self._frame_id = costmap.frame_id
            self.n_frontier_cells = 0
            t = _TILE
            self._counts = np.zeros(((h + t - 1) // t, (w + t - 1) // t), dtype=np.int32)
            bbox = None
        if bbox is None:
            bbox = (0, h, 0, w)
        y0, y1, x0, x1 = bbox
        if y1 <= y0:
            return
        self.memo.changed()  # `bbox` holds every cell whose lethal or unknown state changed
        self.n_frontier_cells += fk.update_frontier_region(
            costmap.lethal,
            costmap.unknown,
            self.frontier,
            self._counts,
            _TILE,
            max(0, y0 - 1),
            min(h, y1 + 1),
            max(0, x0 - 1),
            min(w, x1 + 1),
        )

    def _carry_seen(self, costmap: GlobalCostmap) -> None:
        """Move the look counts into the costmap's new frame (it grew or was reset)."""
        old, self.seen = self.seen, np.zeros(costmap.shape, dtype=np.uint8)
        if old.size == 0 or costmap.resolution <= 0:
            self._seen_origin = costmap.origin.copy()
            return
        oy, ox = (
            int(round(v)) for v in (self._seen_origin - costmap.origin)[::-1] / costmap.resolution
        )
        h, w = old.shape
        H, W = self.seen.shape
        y0, x0 = max(0, oy), max(0, ox)
        y1, x1 = min(H, oy + h), min(W, ox + w)
        if y1 > y0 and x1 > x0:
            self.seen[y0:y1, x0:x1] = old[y0 - oy : y1 - oy, x0 - ox : x1 - ox]
        self._seen_origin = costmap.origin.copy()

    def observe(self, costmap: GlobalCostmap, pose: np.ndarray, half_fov: float) -> None:
        """Count a close look at the frontier cells the robot at `pose (3,)` sees now: within
        dead_frontier_radius, in the field of view, in line of sight. A cell still frontier
        after dead_frontier_looks of them borders what the laser cannot reveal (the unseen
        inside of an obstacle whose face it glances off): a dead frontier."""
        ix, iy = costmap.world_to_cell(pose[0], pose[1])
        if self.seen.shape != costmap.shape or not costmap.in_bounds(ix, iy):
            return
        dead = fk.observe_frontier(
            self.frontier, costmap.lethal, costmap.unknown, self.seen, iy, ix, float(pose[2]),
            self.params.dead_frontier_radius / costmap.resolution, half_fov,
            self.params.dead_frontier_looks,
        )  # fmt: skip
        if dead:  # a choice reads the counts only against dead_frontier_looks
            self.memo.changed()

    def clusters(self) -> tuple[np.ndarray, np.ndarray]:
        """Frontier cells `(K, 2) [iy, ix]` and their 8-connected cluster labels `(K,)`."""
        cells = fk.frontier_cells(self.frontier, self._counts, _TILE, self.n_frontier_cells)
        shape = self.frontier.shape
        run_id = self.search.new_stamp(shape)
        stamp = self.search.stamp  # new buffers when the grid's shape changed
        labels = fk.label_clusters(self.frontier, cells, self._owner, stamp, run_id)
        self._unk_id = self.search.new_stamp(shape)
        return cells, labels

    def open_cells(
        self, costmap: GlobalCostmap, cells: np.ndarray, area: float | None = None
    ) -> np.ndarray:
        """`(K,) bool`: frontier cells next to unknown space larger than `area` [m^2]
        (None: min_unknown_area; the others border the unseen inside of furniture or walls:
        nothing to explore)."""
        area = self.params.min_unknown_area if area is None else area
        max_cells = int(area / costmap.resolution**2)
        return fk.open_frontier_cells(
            cells, costmap.unknown, self._unk_state, self.search.stamp, self._unk_id, max_cells
        )

    def choose(
        self,
        costmap: GlobalCostmap,
        robot_xy,
        blacklist: list[np.ndarray],
        avoid: list[np.ndarray] = (),
        look_through: bool = False,
        squeeze: bool = False,
        spent: list[np.ndarray] = (),
    ) -> FrontierGoal | None:
        """`find_goal`'s answer, from memory when the same question was asked on the same map
        state (`frontier_memo`: nothing map-sized is done while nothing changes)."""
        cell = costmap.world_to_cell(robot_xy[0], robot_xy[1])
        key = self.memo.question(
            cell, blacklist, avoid, self.closed.points, look_through, squeeze, spent
        )
        found, goal = self.memo.get(key, robot_xy)
        if not found:
            goal = self.find_goal(costmap, robot_xy, blacklist, avoid, look_through, squeeze, spent)
            self.memo.put(key, robot_xy, goal)
        return goal

    def find_goal(
        self,
        costmap: GlobalCostmap,
        robot_xy,
        blacklist: list[np.ndarray],
        avoid: list[np.ndarray] = (),
        look_through: bool = False,
        squeeze: bool = False,
        spent: list[np.ndarray] = (),
    ) -> FrontierGoal | None:
        """Nearest frontier cluster by travel cost through known space, backed off from walls.

        Clusters shorter than min_frontier_size and clusters with a cell within blacklist_radius
        of a blacklisted point are ignored; so are the frontier cells within blacklist_radius
        of a `spent` point (frontier cells arrived at without their going away; the rest of
        the cluster stays) and goal cells within blacklist_radius of an `avoid` point (goals
        already reached without the frontier going away). None when no frontier can be
        reached.

        look_through: the last pass, for frontiers no goal within goal_radius reaches (a room
        behind a door too narrow for the robot's centre to pass): goals up to
        look_through_radius from the frontier, the one nearest it among those that see it, so
        that the laser looks through the door.

        squeeze: the last pass, after the look-through pass (which asked with the wider
        margins first, on the same map): goals the search reaches with squeeze_margin (down
        to the inscribed radius), through a door the robot may not get back out of
        (`PlannerParams.squeeze_margin`); None when squeeze_margin is narrow_margin.
        """
        sx, sy = costmap.world_to_cell(robot_xy[0], robot_xy[1])
        if self.n_frontier_cells == 0 or not costmap.in_bounds(sx, sy):
            return None
        cells, labels = self.clusters()
        area = self.params.look_through_min_area if look_through else None
        # the cells near spent points: no goal serves them, no goal faces them
        spent_cells = self._near(costmap, cells, spent) if len(spent) else None
        sizes, cell_valid = self._valid_cells(costmap, cells, labels, blacklist, area, spent_cells)
        if not cell_valid.any():
            return None
        found, squeezed = self._search(
            costmap, (sx, sy), cells, labels, cell_valid, avoid, look_through, squeeze
        )
        if found.size == 0:
            return None
        if spent_cells is not None:  # the goal faces the nearest cell it may serve
            cells, labels = cells[~spent_cells], labels[~spent_cells]
        goal = self._goal(costmap, robot_xy, found, cells, labels, sizes, look_through)
        return dataclasses.replace(goal, squeeze=True) if squeezed else goal

    def _valid_cells(
        self,
        costmap: GlobalCostmap,
        cells: np.ndarray,
        labels: np.ndarray,
        blacklist,
        area: float | None = None,
        spent_cells: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Cluster sizes [m] (open cells only) and `(K,) bool` the cells a goal may serve.

        A cell is open when it borders unknown space larger than min_unknown_area, was not
        looked at dead_frontier_looks times and is not one of `spent_cells` (`(K,) bool`, or
        None: none); clusters are measured by their open cells. A
        goal may serve an open cell of a big enough cluster that lies outside the inscribed
        radius of every obstacle, where the robot's centre could be. That keeps out the free
        cells a particle filter's map leaves inside a wall's face, between occupied cells,
        next to the wall's unseen inside: goals for them had the robot crawl along the walls.
        A real frontier (a corridor's end, a room seen through a door 0.45 m wide or more)
        has such cells across its middle. explore_lite asks more, a neighbour of cost 0
        (about 0.94 m from obstacles with the thesis's inflation), which would drop doors.
        """
        p = self.params
        is_open = self.open_cells(costmap, cells, area)
        is_open &= self.seen[cells[:, 0], cells[:, 1]] < p.dead_frontier_looks
        if spent_cells is not None:
            is_open &= ~spent_cells
        sizes = np.bincount(labels, weights=is_open) * costmap.resolution
        clear = costmap.inflated[cells[:, 0], cells[:, 1]] < INSCRIBED
        cell_valid = is_open & clear & (sizes[labels] >= p.min_frontier_size)
        if blacklist:
            # A cluster with a cell near a failed goal is dropped whole: a shifted goal on the
            # same frontier would most likely fail the same way.
            near = self._near(costmap, cells, blacklist)
            cell_valid &= ~np.isin(labels, labels[near])
        return sizes, cell_valid

    def _near(self, costmap: GlobalCostmap, cells: np.ndarray, points) -> np.ndarray:
        """`(K,) bool`: the cells `(K, 2) [iy, ix]` within blacklist_radius of some point."""
        xs, ys = costmap.cell_to_world(cells[:, 1], cells[:, 0])
        return fk.within_radius(xs, ys, points, self.params.blacklist_radius)

    def _search(
        self, costmap: GlobalCostmap, start, cells, labels, cell_valid, avoid, look_through,
        squeeze=False,
    ) -> tuple[np.ndarray, bool]:  # fmt: skip
        """Goal cells (near valid frontier cells, not near `avoid` points) reached from the
        robot's cell `start (ix, iy)`: flat indices, nearest first, and whether the squeeze
        attempt reached them. Tried with the planner's margin, then with a wider escape (a
        pocket the map sealed around the robot), then with narrow_margin (frontiers behind
        doors too narrow for the margin); `squeeze`: with squeeze_margin alone (the
        navigator asks after the others found nothing on the same map, nothing off). Gaps
        closed after a failure (`ClosedGaps`) stay closed to every attempt. look_through:
        goals within look_through_radius of the frontier (`choose`)."""
        f = self._look_params if look_through else self.params
        p = self.planner
        args = (costmap, start, cells, labels, cell_valid, avoid, f)
        with self.closed.applied(costmap):  # closed gaps: closed to every attempt
            if squeeze:
                if p.narrow_margin <= p.squeeze_margin:
                    return np.zeros(0, dtype=np.int64), False
                found = self._search_with(*args, narrow_params(p, squeeze=True), None)
                return found, found.size > 0
            found = self._search_with(*args, p, None)
            if found.size == 0:
                found = self._search_with(*args, p, p.pocket_escape_radius)
            if found.size == 0 and p.planner_margin > p.narrow_margin:
                found = self._search_with(*args, narrow_params(p), None)
        return found, False

    def _search_with(self, costmap, start, cells, labels, cell_valid, avoid, f, p, escape_m):
        """One goal search with frontier settings `f`, planner settings `p` and escape radius
        escape_m [m] (None: p's)."""
        res = costmap.resolution
        offsets = cells_in_radius(f.goal_radius, res)
        marked = fk.stamp_targets(
            cells, labels, cell_valid, offsets, costmap.inflated, costmap.unknown,
            self._target, self._owner, planner_blocked_cost(p, costmap.params),
        )  # fmt: skip
        if avoid:
            disc = cells_in_radius(f.blacklist_radius, res)
            h, w = costmap.shape
            for a in avoid:
                ax, ay = costmap.world_to_cell(a[0], a[1])
                ys, xs = disc[:, 0] + ay, disc[:, 1] + ax
                ok = (ys >= 0) & (ys < h) & (xs >= 0) & (xs < w)
                self._target[ys[ok], xs[ok]] = False
        try:
            # Look a little past the first candidate (goal_search_extra goal radii of free
            # travel) so that the goal can be the lowest-cost cell of that cluster.
            extra = p.neutral_cost * f.goal_search_extra * f.goal_radius / res
            return self.search.run(
                costmap, start, self._target, p, extra, allow_unknown=False, escape_m=escape_m
            )
        finally:
            self._target[marked[:, 0], marked[:, 1]] = False

    def _goal(
        self, costmap: GlobalCostmap, robot_xy, found, cells, labels, sizes, look_through=False
    ):
        """The goal among the cells found for the nearest cluster: the lowest-cost one
        (nearest on ties) that sees its frontier; look_through: the one nearest the frontier
        (the wider the view through a door) that sees it."""
        p = self.params
        owners = self._owner.reshape(-1)[found]
        pots = self.search.potential_at(found)
        same = owners == owners[0]
        cand, cand_pot = found[same], pots[same]
        members = cells[labels == owners[0]]
        if look_through:
            cy, cx = np.divmod(cand, costmap.shape[1])
            near = fk.nearest_distance2(cy, cx, members)
            order = np.lexsort((cand_pot, near))
        else:
            cand_cost = costmap.inflated.reshape(-1)[cand]
            order = np.lexsort((cand_pot, cand_cost))
        # The goal must see its frontier: a cell near it but behind a door jamb would be
        # "reached" without the robot ever seeing what lies beyond.
        k = fk.first_with_sight(
            order, cand, members, costmap.lethal, costmap.unknown, costmap.shape[1],
            p.sight_candidates,
        )  # fmt: skip
        best = order[max(k, 0)]
        gy, gx = divmod(int(cand[best]), costmap.shape[1])
        goal_xy = np.array(costmap.cell_to_world(gx, gy), dtype=float)
        fxs, fys = costmap.cell_to_world(members[:, 1], members[:, 0])
        k = int(np.argmin(np.hypot(fxs - goal_xy[0], fys - goal_xy[1])))
        frontier_xy = np.array([fxs[k], fys[k]])
        d = frontier_xy - goal_xy
        if np.hypot(*d) < 1e-9:
            d = goal_xy - np.asarray(robot_xy[:2], dtype=float)
        path_cells = self.search.path_to(int(cand[best]))
        pxs, pys = costmap.cell_to_world(path_cells[:, 1], path_cells[:, 0])
        return FrontierGoal(
            path_xy=np.column_stack((pxs, pys)),
            goal_xy=goal_xy,
            yaw=math.atan2(d[1], d[0]),
            frontier_xy=frontier_xy,
            cluster_size_m=float(sizes[owners[0]]),
            travel_cost=float(cand_pot[best]),
            n_clusters=int(np.count_nonzero(sizes >= p.min_frontier_size)),
            look_through=look_through,
        )

    def frontier_near(self, costmap: GlobalCostmap, xy, radius_m: float) -> bool:
        """True while frontier cells remain within `radius_m` of a point (map frame)."""
        ix, iy = costmap.world_to_cell(xy[0], xy[1])
        return bool(
            fk.any_in_disc(self.frontier, iy, ix, cells_in_radius(radius_m, costmap.resolution))
        )
