"""The robot's navigation stack: explore_lite goals + move_base (planners, recovery, safety)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.explore import costmap_kernels as ck
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.dwa import Command, DwaPlanner, drive
from worker.explore.frontiers import FrontierGoal, FrontierSearch
from worker.explore.params import ExploreParams
from worker.explore.planner import GlobalPlanner, path_length
from worker.explore.safety import SafetyController
from worker.explore.shim import HeadingShim


@dataclass(frozen=True)
class GoalRecord:
    """One exploration goal and how it ended (map frame)."""

    t_start: float  # [s]
    t_end: float  # [s]
    x: float  # [m]
    y: float  # [m]
    # "reached" (arrived and turned to the frontier), "explored" (its frontier vanished on
    # the way), "failed" (no plan, no legal command or no progress for too long), "replaced"
    # (a nearer frontier came up), "dropped" (no frontier reachable any more)
    status: str
    detail: str = ""


@dataclass(frozen=True)
class NavCommand:
    """The velocity to send and what the stack is doing."""

    v: float  # [m/s]
    w: float  # [rad/s]
    status: str  # "driving", "aligning", "safety", "recovering", "planning", "no_frontier"


@dataclass
class NavStats:
    """Counters of one run."""

    goals: list[GoalRecord] = field(default_factory=list)
    recoveries: int = 0  # local costmap clearings + replans after the controller failed
    plan_failures: int = 0
    consecutive_failures: int = 0  # given-up goals since the last success


class Navigator:
    """Chooses frontier goals, plans, follows the plan with the DWA, recovers, stays safe.

    Fed only with the SLAM map (`update_map`) and the SLAM pose plus the latest scan (`step`).
    """

    def __init__(self, params: ExploreParams, angles: np.ndarray, range_max: float):
        self.params = params
        self.angles = np.asarray(angles, dtype=float)
        self.range_max = float(range_max)
        self.costmap = GlobalCostmap(params)
        self.frontiers = FrontierSearch(params)
        self.planner = GlobalPlanner(params)
        self.dwa = DwaPlanner(params)
        self.shim = HeadingShim(params)
        self.safety = SafetyController(params, self.angles, self.range_max)
        self.local: LocalCostmap | None = None
        self.stats = NavStats()
        self.blacklist: list[np.ndarray] = []
        # (frontier, goal) of goals reached whose frontier did not vanish
        self._arrived_at: list[tuple[np.ndarray, np.ndarray]] = []
        self._blacklist_retries = params.blacklist_retries
        self.goal: FrontierGoal | None = None
        self.path: np.ndarray | None = None
        self._goal_t0 = 0.0
        self._next_choice_t = 0.0
        self._next_plan_t = 0.0
        self._plan_fail_since: float | None = None
        self._ctrl_fail_since: float | None = None
        self._recovered = False
        self._best_gap = math.inf
        self._progress_t = 0.0
        self._frontier_changed = False
        self._map_updated = False
        self._half_fov = float(np.max(np.abs(self.angles))) - 0.05  # [rad]
        self._beams_box: tuple[float, float, float, float] | None = None
        self._trail: list[np.ndarray] = []  # (2,) positions 5 cm apart, newest last
        self._retrace_to: np.ndarray | None = None
        self._retrace_until = 0.0

    # --- map ---
    def update_map(self, prob, resolution: float, origin, full: bool) -> None:
        """Refresh costmap and frontiers from the SLAM map: where the beams since the last
        update reached (the map cannot have changed elsewhere), or everywhere when full."""
        window = None
        if not full and self.costmap.resolution == resolution and self._beams_box is not None:
            m = 2 * resolution
            b = self._beams_box
            window = (b[0] - m, b[1] - m, b[2] + m, b[3] + m)
        self._beams_box = None
        changed = self.costmap.update(prob, resolution, origin, window)
        self.frontiers.update(self.costmap, changed)
        if changed[1] > changed[0]:
            self._frontier_changed = True
        self._map_updated = True
        if self.local is None:
            self.local = LocalCostmap(self.params, resolution)

    # --- control ---
    def step(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges) -> NavCommand:
        """One control period: the command for pose `(3,)` [x, y, theta] (map frame)."""
        p = self.params
        self._grow_beams_box(pose, ranges)
        if self.local is None:
            return NavCommand(0.0, 0.0, "planning")
        self.local.add_scan(t, pose, ranges, self.angles, self.range_max)
        self.local.build(pose[0], pose[1], self.costmap, pose[2])
        self._grow_trail(pose)
        if self._map_updated:
            self._map_updated = False
            self.frontiers.observe(self.costmap, pose, self._half_fov)
        if self.safety.active(t):
            return NavCommand(
                *self._safe_override(pose, self.safety.check(t, ranges, 0.0), v0, w0), "safety"
            )
        if self._retrace_to is not None:
            vw = self._retrace(t, pose)
            if vw is not None:
                return NavCommand(vw[0], vw[1], "recovering")
        self._check_goal_still_open(t)
        if self.goal is None or t >= self._next_choice_t:
            self._choose(t, pose)
            if self.goal is None:
                return NavCommand(0.0, 0.0, "no_frontier")
        if self.path is None or t >= self._next_plan_t:
            self._plan(t, pose)
        if self.path is None:
            if t - self._plan_fail_since >= p.planner_patience:
                self._give_up(t, "no plan")
            return NavCommand(0.0, 0.0, "planning")
        shim = self.shim.command(pose, w0, self.path, self.local)
        if shim is not None:
            self._ctrl_fail_since = None
            if self._no_progress(t, pose):
                self._give_up(t, "no progress")
                return NavCommand(0.0, 0.0, "recovering")
            status = "aligning" if shim[2] == "rotate" else "recovering"
            return NavCommand(shim[0], shim[1], status)
        # Frontier goals carry no heading requirement: with a 270 degree laser the robot sees
        # the frontier on arrival, and turning in place in a doorway is how robots got stuck.
        cmd = self.dwa.command(pose, v0, w0, self.local, None)
        if not cmd.legal:
            # the map's obstacles may sit a cell nearer than the real ones (rounded hits):
            # with nothing legal, trust the scans alone, as the thesis's local costmap did
            self.local.build(pose[0], pose[1], self.costmap, pose[2], use_map=False)
            cmd = self.dwa.command(pose, v0, w0, self.local, None)
            if cmd.kind in ("escape", "rotate"):
                # not blind: backing up or turning sweeps what the laser does not see
                cmd = Command(0.0, 0.0, False, "none")
        if cmd.kind == "aligned":
            self._finish(t, "reached")
            return NavCommand(0.0, 0.0, "aligning")
        if not cmd.legal:
            vw = self._unwedge(pose)
            if vw is not None:
                return NavCommand(vw[0], vw[1], "recovering")
            return self._controller_failed(t)
        self._ctrl_fail_since = None
        self._recovered = False
        if self._no_progress(t, pose):
            self._give_up(t, "no progress")
            return NavCommand(0.0, 0.0, "recovering")
        override = self.safety.check(t, ranges, cmd.v)
        if override is not None:
            return NavCommand(
                *self._safe_override(pose, override, v0, w0, (cmd.v, cmd.w)), "safety"
            )
        return NavCommand(cmd.v, cmd.w, "aligning" if cmd.kind == "align" else "driving")

    def _safe_override(
        self, pose: np.ndarray, vw, v0: float, w0: float, planned=(0.0, 0.0)
    ) -> tuple[float, float]:
        """The safety controller backs off blind (the laser does not see behind): check the
        manoeuvre against the local costmap, which holds the map's obstacles; if it would hit
        something, only turn; if that too, let the local planner turn or back off its way;
        if it cannot either, its own (collision-checked) `planned` command, as the only way
        out of the corner."""
        p = self.params
        L = self.local
        for v, w in (vw, (0.0, vw[1])):
            if dk.motion_legal(
                float(pose[0]), float(pose[1]), float(pose[2]), v, w, p.safety_backoff_time,
                L.lethal, L.near, L.inner, float(L.origin[0]), float(L.origin[1]),
                L.resolution, p.footprint_half_m, p.sim_granularity,
            ):  # fmt: skip
                return v, w
        if self.dwa.path_xy is not None:
            cmd = self.dwa.command(pose, v0, w0, L, None, no_forward=True)
            if cmd.legal:
                return cmd.v, cmd.w
        return planned

    def _unwedge(self, pose: np.ndarray) -> tuple[float, float] | None:
        """Out of contact: the footprint overlaps an obstacle cell (the scan's or the map's) at
        the robot's own pose, so every motion collides, backing away included (in clutter the
        DWA's unpadded pass can end a few centimetres from furniture, and a cell is 5 cm).
        The slow motion (back, forward, turn, for one second) that takes the footprint
        farthest from the cells it touches without touching any other, backwards first on
        ties (sliding along an obstacle at its side is a way out too); None when it touches
        nothing, or every such motion would take it nearer to them."""
        p = self.params
        L = self.local
        x, y, th = (float(v) for v in pose)
        half = p.footprint_half_m
        L.build(x, y, self.costmap, th)
        if not ck.footprint_collides(
            L.lethal, L.near, L.inner, float(L.origin[0]), float(L.origin[1]), L.resolution,
            x, y, th, half,
        ):  # fmt: skip
            return None
        blocked = L.lethal.copy()
        L.build(x, y, self.costmap, th, clear_touching=True)  # same window: same origin
        iy, ix = np.nonzero(blocked & ~L.lethal)
        if iy.size == 0:
            return None
        cx = L.origin[0] + (ix + 0.5) * L.resolution
        cy = L.origin[1] + (iy + 0.5) * L.resolution
        best, best_gap = None, _square_gap(cx, cy, x, y, th, half) - 1e-6
        duration = 1.0
        for v in (p.escape_vel, 0.0, p.min_vel_x):
            for w in (-p.min_in_place_vel_theta, 0.0, p.min_in_place_vel_theta):
                if (v, w) == (0.0, 0.0) or not dk.motion_legal(
                    x, y, th, v, w, duration, L.lethal, L.near, L.inner, float(L.origin[0]),
                    float(L.origin[1]), L.resolution, half, p.sim_granularity,
                ):  # fmt: skip
                    continue
                ex, ey, eth = drive(x, y, th, v, w, duration, 20)
                gap = _square_gap(cx, cy, ex, ey, eth, half)
                if gap > best_gap:
                    best, best_gap = (v, w), gap
        return best

    def _grow_beams_box(self, pose: np.ndarray, ranges) -> None:
        """Bounding box `(x0, y0, x1, y1)` [m] of the robot and its beams' end points."""
        a = self.angles + pose[2]
        xs = pose[0] + ranges * np.cos(a)
        ys = pose[1] + ranges * np.sin(a)
        box = (
            min(xs.min(), pose[0]), min(ys.min(), pose[1]),
            max(xs.max(), pose[0]), max(ys.max(), pose[1]),
        )  # fmt: skip
        b = self._beams_box
        self._beams_box = box if b is None else (
            min(b[0], box[0]), min(b[1], box[1]), max(b[2], box[2]), max(b[3], box[3])
        )  # fmt: skip

    def _check_goal_still_open(self, t: float) -> None:
        """A goal whose frontier disappeared (the robot saw the place on the way) is done."""
        if (
            self.goal is not None
            and self._frontier_changed
            and not self.frontiers.frontier_near(
                self.costmap, self.goal.frontier_xy, self.params.blacklist_radius
            )
        ):
            self._finish(t, "explored")
        self._frontier_changed = False

    def _choose(self, t: float, pose: np.ndarray) -> None:
        p = self.params
        self._next_choice_t = t + p.frontier_period
        avoid = [g for _, g in self._arrived_at]
        new = self.frontiers.choose(self.costmap, pose[:2], self.blacklist, avoid)
        if new is None and self.blacklist and self._blacklist_retries > 0:
            # before giving up on the building, give the blacklisted frontiers another chance
            self._blacklist_retries -= 1
            self.blacklist.clear()
            self._arrived_at.clear()
            new = self.frontiers.choose(self.costmap, pose[:2], self.blacklist)
        if new is None:
            if self.goal is not None:
                self._end_goal(t, "dropped", "no reachable frontier left")
            self.goal = None
            return
        if self.goal is not None:
            if np.hypot(*(new.goal_xy - self.goal.goal_xy)) <= 1.0:
                return  # same goal, keep its plan and progress timers
            # Switch only to a clearly nearer frontier: two about equally near ones must not
            # make the robot dither between them.
            remaining = path_length(self.path) / self.costmap.resolution * p.neutral_cost
            if self.path is None or new.travel_cost >= p.goal_switch_ratio * remaining:
                return
            self._end_goal(t, "replaced", "a nearer frontier")
        self.goal = new
        self._goal_t0 = t
        self.path = new.path_xy  # the frontier search's own path: the first plan
        self.dwa.set_plan(self.path)
        self._next_plan_t = t + 1.0 / p.planner_frequency
        self._plan_fail_since = None
        self._ctrl_fail_since = None
        self._best_gap = math.inf
        self._progress_t = t

    def _plan(self, t: float, pose: np.ndarray) -> None:
        self._next_plan_t = t + 1.0 / self.params.planner_frequency
        path = self.planner.plan(self.costmap, pose[:2], self.goal.goal_xy)
        if path is None:
            self.stats.plan_failures += 1
            if self._plan_fail_since is None:
                self._plan_fail_since = t
            self.path = None
            self._next_plan_t = t + 1.0 / self.params.controller_frequency
        else:
            self._plan_fail_since = None
            self.path = path
        self.dwa.set_plan(self.path)

    def _controller_failed(self, t: float) -> NavCommand:
        """move_base: no legal command -> clear the local costmap and replan; later give up."""
        if self._ctrl_fail_since is None:
            self._ctrl_fail_since = t
        elapsed = t - self._ctrl_fail_since
        if elapsed >= self.params.controller_patience:
            self._give_up(t, "no legal command")
        elif not self._recovered and elapsed >= 1.0:
            self._recovered = True
            self.stats.recoveries += 1
            self.local.clear()
            self._next_plan_t = t  # replan now
            self._start_retrace(t)
        return NavCommand(0.0, 0.0, "recovering")

    def _no_progress(self, t: float, pose: np.ndarray) -> bool:
        """explore_lite's progress_timeout: the goal got no nearer for too long."""
        gap = float(np.hypot(*(self.goal.goal_xy - pose[:2])))
        if gap < self._best_gap - 0.1:
            self._best_gap = gap
            self._progress_t = t
        return t - self._progress_t >= self.params.progress_timeout

    def _finish(self, t: float, status: str) -> None:
        """Goal done. A frontier still there after the robot arrived is approached from
        elsewhere next time, and blacklisted after three such arrivals (the SLAM map updates
        only after some motion, so one arrival is not enough to tell)."""
        r = self.params.blacklist_radius
        f = self.goal.frontier_xy
        if status == "reached" and self.frontiers.frontier_near(self.costmap, f, r):
            # next time, a goal elsewhere near that frontier; after a few, drop the frontier
            self._arrived_at.append((f.copy(), self.goal.goal_xy.copy()))
            if sum(np.hypot(*(f - q)) <= 2 * r for q, _ in self._arrived_at) >= 3:
                self.blacklist.append(f.copy())
        self.stats.consecutive_failures = 0
        self._end_goal(t, status)

    def _grow_trail(self, pose: np.ndarray) -> None:
        if not self._trail or np.hypot(*(pose[:2] - self._trail[-1])) >= 0.05:
            self._trail.append(pose[:2].copy())
            if len(self._trail) > 200:
                del self._trail[:100]

    def _start_retrace(self, t: float) -> None:
        """Recovery: back out along the way the robot came (that space was free), ~0.8 m."""
        if len(self._trail) < 4:
            return
        self._retrace_to = self._trail[max(0, len(self._trail) - 17)].copy()
        self._retrace_until = t + self.params.retrace_time
        self.stats.recoveries += 1

    def _retrace(self, t: float, pose: np.ndarray) -> tuple[float, float] | None:
        """Reverse towards the retrace point, checked against the local costmap; None: done."""
        p = self.params
        d = self._retrace_to - pose[:2]
        if np.hypot(*d) < 0.1 or t >= self._retrace_until:
            self._retrace_to = None
            self._trail.clear()
            return None
        # backwards: the robot's rear points at the target
        err = wrap_angle(math.atan2(d[1], d[0]) + math.pi - pose[2])
        w = max(-p.max_vel_theta, min(p.max_vel_theta, 1.5 * err))
        v = p.escape_vel * 1.5 if abs(err) < 0.6 else 0.0
        L = self.local
        for vv, ww in ((v, w), (0.0, w), (v, 0.0)):
            if (vv, ww) != (0.0, 0.0) and dk.motion_legal(
                float(pose[0]), float(pose[1]), float(pose[2]), vv, ww, 0.5,
                L.lethal, L.near, L.inner, float(L.origin[0]), float(L.origin[1]),
                L.resolution, p.footprint_half_m, p.sim_granularity,
            ):  # fmt: skip
                return vv, ww
        self._retrace_to = None
        return None

    def _give_up(self, t: float, why: str) -> None:
        self._start_retrace(t)
        self.blacklist.append(self.goal.frontier_xy.copy())
        self.stats.consecutive_failures += 1
        self._end_goal(t, "failed", why)

    def _end_goal(self, t: float, status: str, detail: str = "") -> None:
        g = self.goal
        self.stats.goals.append(
            GoalRecord(self._goal_t0, t, float(g.goal_xy[0]), float(g.goal_xy[1]), status, detail)
        )
        self.goal = None
        self.path = None
        self.dwa.set_plan(None)
        self.shim.reset()
        self._next_choice_t = t


def _square_gap(px: np.ndarray, py: np.ndarray, x: float, y: float, th: float, half: float):
    """[m] the least distance from the points `(K,)` to the square footprint (half side
    `half`) at (x, y, th); 0 for a point inside."""
    dx, dy = px - x, py - y
    c, s = math.cos(th), math.sin(th)
    u = np.maximum(np.abs(dx * c + dy * s) - half, 0.0)
    v = np.maximum(np.abs(-dx * s + dy * c) - half, 0.0)
    return float(np.min(np.hypot(u, v)))
