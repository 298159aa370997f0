"""The robot's navigation stack: explore_lite goals + move_base (planners, recovery, safety)."""

from __future__ import annotations

import numpy as np

from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.door import DoorPass
from worker.explore.dwa import DwaPlanner
from worker.explore.frontiers import FrontierGoal, FrontierSearch
from worker.explore.goal_choice import GoalChooser
from worker.explore.nav_recovery import RecoveryLayer
from worker.explore.nav_state import (
    FrontierMemory,
    GoalRecord,
    NavCommand,
    NavState,
    NavStats,
    Pursuit,
    Retrace,
    grown_box,
)
from worker.explore.params import ExploreParams
from worker.explore.planner import (
    ClosedGaps,
    DijkstraSearch,
    GlobalPlanner,
    path_length,
)
from worker.explore.recovery import Trail, safe_override, unwedge
from worker.explore.safety import SafetyController
from worker.explore.shim import HeadingShim

__all__ = ["GoalRecord", "NavCommand", "NavState", "NavStats", "Navigator"]


class Navigator(RecoveryLayer):
    """Chooses frontier goals, plans, follows the plan with the DWA, recovers, stays safe.

    Fed only with the SLAM map (`update_map`) and the SLAM pose plus the latest scan (`step`).
    `state` says what it is doing (nav_state.TRANSITIONS: how and why that changes); the
    goal pursued is `pursuit`, a back-out under way `retrace`.
    """

    def __init__(
        self, params: ExploreParams, angles: np.ndarray, range_max: float, range_noise: float = 0.0
    ):
        """range_noise: the laser's range noise sigma [m] (its data sheet's accuracy): with
        noise, the safety controller median-filters the readings (safety_median_beams) and
        the stack drives with `params.for_range_noise` (the door passage on, noisy marks
        kept out of free cells)."""
        params = params.for_range_noise(range_noise)
        self.params = params
        self.angles = np.asarray(angles, dtype=float)
        self.range_max = float(range_max)
        self.costmap = GlobalCostmap(params.costmap, params.doors.door_align)
        # narrow gaps the robot failed to pass: closed to both narrow fallbacks
        self.closed = ClosedGaps()
        # one set of map-sized Dijkstra buffers for the goal search and the planner (each
        # reads its results right after its own search): 16 bytes a cell less
        search = DijkstraSearch()
        c, dwa, rec, safe = params.costmap, params.dwa, params.recovery, params.safety
        self.frontiers = FrontierSearch(params.frontiers, params.planner, self.closed, search)
        self.planner = GlobalPlanner(params.planner, self.closed, search)
        self.dwa = DwaPlanner(dwa, c)
        self.shim = HeadingShim(dwa, c, rec)
        back_out_speed = rec.back_out_speed_ratio * dwa.escape_vel
        self.door = DoorPass(
            params.doors, c, dwa, back_out_speed, safe.safety_distance, range_noise
        )
        median = safe.safety_median_beams if range_noise > 0.0 else 1
        self.safety = SafetyController(safe, c, dwa, self.angles, self.range_max, median)
        self.local: LocalCostmap | None = None
        self.stats = NavStats()
        self.state = NavState.WAITING
        self.pursuit: Pursuit | None = None
        self.retrace: Retrace | None = None
        self.memory = FrontierMemory(params.navigator.blacklist_retries)
        self.chooser = GoalChooser(
            self.frontiers,
            self.closed,
            self.memory,
            params.frontiers.look_through_radius,
            params.navigator.closed_gap_reopens,
        )
        self.trail = Trail(rec)
        self._next_choice_t = 0.0  # [s] when to choose the frontier again
        # the local costmap was cleared since the DWA last found a legal command (any goal)
        self._recovered = False
        self._frontier_changed = False
        self._map_updated = False
        self._half_fov = (
            float(np.max(np.abs(self.angles))) - params.frontiers.look_fov_margin
        )  # [rad]
        self._beams_box: tuple[float, float, float, float] | None = None
        self._last_scan: tuple[np.ndarray, np.ndarray] | None = None  # (pose, ranges)
        self._planned_forward = False  # the last command: the local planner's, forwards

    @property
    def goal(self) -> FrontierGoal | None:
        """The frontier goal pursued, or None."""
        return None if self.pursuit is None else self.pursuit.goal

    @property
    def path(self) -> np.ndarray | None:
        """`(K, 2) [x, y]` the plan being followed, or None."""
        return None if self.pursuit is None else self.pursuit.path

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
        scan = None
        if self.params.costmap.obstacle_layer and self._last_scan is not None:
            scan = (*self._last_scan, self.angles, self.range_max)
        changed = self.costmap.update(prob, resolution, origin, window, scan)
        self.frontiers.update(self.costmap, changed)
        if changed[1] > changed[0]:
            self._frontier_changed = True
            self.planner.map_changed()  # plans kept only while the costmap stays the same
        self._map_updated = True
        if self.local is None:
            self.local = LocalCostmap(self.params.costmap, self.params.dwa, resolution)
            self._enter(NavState.IDLE)

    # --- control ---
    def step(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges) -> NavCommand:
        """One control period: the command for pose `(3,)` [x, y, theta] (map frame)."""
        self._grow_beams_box(pose, ranges)
        self._last_scan = (np.array(pose, dtype=float), np.asarray(ranges, dtype=float))
        if self.state is NavState.WAITING:
            return NavCommand(0.0, 0.0, "planning")
        self.local.add_scan(t, pose, ranges, self.angles, self.range_max)
        self.local.build(pose[0], pose[1], self.costmap, pose[2])
        self.trail.grow(pose, self._planned_forward)
        self._planned_forward = False
        if self._map_updated:
            self._map_updated = False
            self.frontiers.observe(self.costmap, pose, self._half_fov)
        if self.state is NavState.SAFETY:
            if self.safety.active(t):
                vw = safe_override(
                    self.params.safety.safety_backoff_time, self.local, self.dwa, pose,
                    self.safety.check(t, ranges, 0.0),
                    v0, w0,
                )  # fmt: skip
                return NavCommand(*vw, "safety")
            self._enter(NavState.DRIVING)
        if self.state is NavState.RETRACING:
            vw = self._retrace(t, pose)
            if vw is not None:
                return NavCommand(vw[0], vw[1], "recovering")
        return self._pursue(t, pose, v0, w0, ranges)

    def _pursue(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges) -> NavCommand:
        """The goal layer: end a goal whose frontier vanished, re-choose the frontier when
        due, replan when due, then drive along the plan."""
        self._check_goal_still_open(t)
        if self.pursuit is None or t >= self._next_choice_t:
            self._choose(t, pose)
            if self.pursuit is None:
                return NavCommand(0.0, 0.0, "no_frontier")
        g = self.pursuit
        if g.path is None or t >= g.next_plan_t:
            self._plan(t, pose)
        if g.path is None:
            if t - g.plan_fail_since >= self.params.navigator.planner_patience:
                self._give_up(t, "no plan")
            return NavCommand(0.0, 0.0, "planning")
        return self._drive(t, pose, v0, w0, ranges)

    def _drive(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges) -> NavCommand:
        """Follow the plan: the door passage through a tight door ahead (door_align), the
        heading shim when the plan lies behind, else the DWA; the safety controller has the
        last word on the DWA's and the door passage's forward commands."""
        g = self.pursuit
        if self.params.recovery.trap_reach > 0.0:
            out = self.trail.closed_behind(self.local, self.params.recovery.trap_reach)
            if out is not None:
                # the gap behind the robot is too narrow to drive back through: back out
                # now, on the line it came in by, before it turns away from it (once)
                self.trail.unchecked()
                self._give_up(t, "trapped", pose, out)
                return NavCommand(0.0, 0.0, "recovering")
        # the door passage: on with a noisy laser, and for a goal of the squeeze pass, which
        # the DWA's arcs bring to a door too tight to enter at an angle
        shim = (
            self.door.command(pose, g.path, self.costmap, self.local)
            if self.params.doors.door_align or g.goal.squeeze
            else None
        )
        if shim is None:
            shim = self.shim.command(pose, w0, g.path, self.local)
        if shim is not None:
            return self._follow_shim(t, pose, v0, w0, ranges, shim)
        return self._follow_dwa(t, pose, v0, w0, ranges)

    def _follow_shim(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges, shim):
        """Drive by the door passage's or the heading shim's `(v, w, kind)`."""
        self._command_found()
        if self._no_progress(t, pose):
            self._give_up(t, "no progress", pose)
            return NavCommand(0.0, 0.0, "recovering")
        if shim[2] == "door":
            # the door passage judges its motions on the SLAM map; what the laser sees in
            # front of the robot (a chair leg the map lacks, a jamb the pose's error hides)
            # is the safety controller's to veto, as for the DWA's commands
            vetoed = self._safety_veto(t, pose, ranges, shim[0], v0, w0, (0.0, 0.0))
            if vetoed is not None:
                return vetoed
        status = {
            "rotate": "aligning",
            "door_turn": "aligning",
            "door": "driving",
            "door_reverse": "driving",
        }.get(shim[2], "recovering")
        return NavCommand(shim[0], shim[1], status)

    def _follow_dwa(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges):
        """Drive by the DWA: unwedge or recover when it has nothing legal."""
        cmd = self.dwa.command_or_scans_only(pose, v0, w0, self.local, self.costmap)
        if cmd.kind == "aligned":
            self._finish(t, "reached")
            return NavCommand(0.0, 0.0, "aligning")
        if not cmd.legal:
            vw = unwedge(self.params.recovery, self.params.dwa, self.local, self.costmap, pose)
            if vw is not None:
                self._enter(NavState.ESCAPING)
                return NavCommand(vw[0], vw[1], "recovering")
            return self._controller_failed(t, pose)
        self._command_found()
        self._recovered = False
        if self._no_progress(t, pose):
            self._give_up(t, "no progress", pose)
            return NavCommand(0.0, 0.0, "recovering")
        vetoed = self._safety_veto(t, pose, ranges, cmd.v, v0, w0, (cmd.v, cmd.w))
        if vetoed is not None:
            return vetoed
        self._planned_forward = cmd.v > 0.0
        return NavCommand(cmd.v, cmd.w, "aligning" if cmd.kind == "align" else "driving")

    def _safety_veto(
        self, t: float, pose: np.ndarray, ranges, v: float, v0: float, w0: float, planned
    ) -> NavCommand | None:
        """The safety controller's override of a command driving at v, checked against the
        local costmap (`safe_override`; `planned`, its last resort), or None: drive on."""
        override = self.safety.check(t, ranges, v)
        if override is None:
            return None
        self._enter(NavState.SAFETY)
        backoff = self.params.safety.safety_backoff_time
        vw = safe_override(backoff, self.local, self.dwa, pose, override, v0, w0, planned)
        return NavCommand(*vw, "safety")

    # --- transitions ---
    def _enter(self, state: NavState) -> None:
        """Change `state`, counting the transition (nav_state.TRANSITIONS says why)."""
        if state is not self.state:
            self.stats.transitions[(self.state, state)] += 1
            self.state = state

    def _command_found(self) -> None:
        """A command to follow the plan: whatever failed before, the robot drives again."""
        self.pursuit.ctrl_fail_since = None
        self._enter(NavState.DRIVING)

    def _goal_layer_state(self) -> NavState:
        """The goal layer's state by its data."""
        g = self.pursuit
        if g is None:
            return NavState.IDLE
        if g.path is None:
            return NavState.PLANNING
        return NavState.DRIVING if g.ctrl_fail_since is None else NavState.RECOVERING

    def _grow_beams_box(self, pose: np.ndarray, ranges) -> None:
        """Bounding box `(x0, y0, x1, y1)` [m] of the robot and its beams' end points."""
        self._beams_box = grown_box(self._beams_box, pose, ranges, self.angles)

    def _check_goal_still_open(self, t: float) -> None:
        """A goal whose frontier disappeared (the robot saw the place on the way) is done."""
        if (
            self.pursuit is not None
            and self._frontier_changed
            and not self.frontiers.frontier_near(
                self.costmap, self.pursuit.goal.frontier_xy, self.params.frontiers.blacklist_radius
            )
        ):
            self._finish(t, "explored")
        self._frontier_changed = False

    def _choose(self, t: float, pose: np.ndarray) -> None:
        """Choose the frontier: keep the goal, switch to a clearly nearer one, or drop it."""
        p = self.params
        self._next_choice_t = t + p.navigator.frontier_period
        new = self.chooser.choose(self.costmap, pose)
        g = self.pursuit
        if new is None:
            if g is not None:
                self._end_goal(t, "dropped", "no reachable frontier left")
            self._enter(NavState.EXHAUSTED)
            return
        if g is not None:
            if np.hypot(*(new.goal_xy - g.goal.goal_xy)) <= p.navigator.same_goal_distance:
                return  # same goal, keep its plan and progress timers
            # Switch only to a clearly nearer frontier: two about equally near ones must not
            # make the robot dither between them.
            remaining = path_length(g.path) / self.costmap.resolution * p.planner.neutral_cost
            if g.path is None or new.travel_cost >= p.navigator.goal_switch_ratio * remaining:
                return
            self._end_goal(t, "replaced", "a nearer frontier")
        # the frontier search's own path: the first plan
        next_plan_t = t + 1.0 / p.navigator.planner_frequency
        self.pursuit = Pursuit(new, t, new.path_xy, next_plan_t, progress_t=t)
        self.door.new_goal()
        self.dwa.set_plan(new.path_xy)
        self._enter(NavState.DRIVING)

    def _plan(self, t: float, pose: np.ndarray) -> None:
        g = self.pursuit
        g.next_plan_t = t + 1.0 / self.params.navigator.planner_frequency
        path = self.planner.plan(self.costmap, pose[:2], g.goal.goal_xy, g.goal.squeeze)
        if path is None:
            self.stats.plan_failures += 1
            if g.plan_fail_since is None:
                g.plan_fail_since = t
            g.next_plan_t = t + 1.0 / self.params.dwa.controller_frequency
        else:
            g.plan_fail_since = None
        g.path = path
        self.dwa.set_plan(path)
        if path is None or self.state is NavState.PLANNING:
            self._enter(self._goal_layer_state())

    def _no_progress(self, t: float, pose: np.ndarray) -> bool:
        """The goal pursued got no nearer for progress_timeout (`Pursuit.no_progress`)."""
        p = self.params.navigator
        return self.pursuit.no_progress(t, pose, p.progress_step, p.progress_timeout)

    def _finish(self, t: float, status: str) -> None:
        """Goal done. A frontier still there after the robot arrived is approached from
        elsewhere next time, and blacklisted after blacklist_arrivals such arrivals (the SLAM
        map updates only after some motion, so one arrival is not enough to tell)."""
        p = self.params
        goal = self.pursuit.goal
        f, r = goal.frontier_xy, p.frontiers.blacklist_radius
        if status == "reached" and self.frontiers.frontier_near(self.costmap, f, r):
            self.memory.arrived(
                f, goal.goal_xy, r, p.navigator.blacklist_arrivals, goal.look_through
            )
        self.stats.consecutive_failures = 0
        self._end_goal(t, status)

    def _give_up(self, t: float, why: str, pose: np.ndarray | None = None, out=None) -> None:
        """The goal given up: back out, blacklist its frontier; when the robot could not get
        on (no progress, no legal command) with its plan through a gap under the planner's
        margin near it, close that gap to the narrow fallback (`ClosedGaps`)."""
        g = self.pursuit
        if pose is not None and g.path is not None:
            self.closed.close(
                self.costmap,
                self.params.planner,
                g.path,
                pose[:2],
                self.params.planner.closed_gap_radius,
            )
        self._start_retrace(t, pose, out)
        self.memory.give_up(g.goal.frontier_xy, g.goal.look_through)
        self.stats.consecutive_failures += 1
        self._end_goal(t, "failed", why)

    def _end_goal(self, t: float, status: str, detail: str = "") -> None:
        g = self.pursuit
        x, y = float(g.goal.goal_xy[0]), float(g.goal.goal_xy[1])
        if g.goal.look_through:
            detail = "look-through" + (f": {detail}" if detail else "")
        elif g.goal.squeeze:
            detail = "squeeze" + (f": {detail}" if detail else "")
        self.stats.goals.append(GoalRecord(g.t0, t, x, y, status, detail))
        self.pursuit = None
        self.dwa.set_plan(None)
        self.shim.reset()
        self.door.reset()
        self._next_choice_t = t
        if self.retrace is None:
            self._enter(NavState.IDLE)
