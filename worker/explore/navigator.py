"""The robot's navigation stack: explore_lite goals + move_base (planners, recovery, safety)."""

from __future__ import annotations

import numpy as np

from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.door import DoorPass
from worker.explore.dwa import Command, DwaPlanner
from worker.explore.frontiers import FrontierGoal, FrontierSearch
from worker.explore.nav_state import (
    FrontierMemory,
    GoalRecord,
    NavCommand,
    NavState,
    NavStats,
    Pursuit,
    Retrace,
)
from worker.explore.params import ExploreParams
from worker.explore.planner import (
    ClosedGaps,
    DijkstraSearch,
    GlobalPlanner,
    path_length,
    remaining_length,
)
from worker.explore.recovery import Trail, back_out, safe_override, unwedge
from worker.explore.safety import SafetyController
from worker.explore.shim import HeadingShim

__all__ = ["GoalRecord", "NavCommand", "NavState", "NavStats", "Navigator"]


class Navigator:
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
        self.costmap = GlobalCostmap(params)
        # narrow gaps the robot failed to pass: closed to both narrow fallbacks
        self.closed = ClosedGaps()
        # one set of map-sized Dijkstra buffers for the goal search and the planner (each
        # reads its results right after its own search): 16 bytes a cell less
        search = DijkstraSearch()
        self.frontiers = FrontierSearch(params, self.closed, search)
        self.planner = GlobalPlanner(params, self.closed, search)
        self.dwa = DwaPlanner(params)
        self.shim = HeadingShim(params)
        self.door = DoorPass(params, range_noise)
        median = params.safety_median_beams if range_noise > 0.0 else 1
        self.safety = SafetyController(params, self.angles, self.range_max, median)
        self.local: LocalCostmap | None = None
        self.stats = NavStats()
        self.state = NavState.WAITING
        self.pursuit: Pursuit | None = None
        self.retrace: Retrace | None = None
        self.memory = FrontierMemory(params.blacklist_retries)
        self._reopens_left = params.closed_gap_reopens  # ClosedGaps cleared when sealed in
        self.trail = Trail(params)
        self._next_choice_t = 0.0  # [s] when to choose the frontier again
        # the local costmap was cleared since the DWA last found a legal command (any goal)
        self._recovered = False
        self._frontier_changed = False
        self._map_updated = False
        self._half_fov = float(np.max(np.abs(self.angles))) - params.look_fov_margin  # [rad]
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
        if self.params.obstacle_layer and self._last_scan is not None:
            scan = (*self._last_scan, self.angles, self.range_max)
        changed = self.costmap.update(prob, resolution, origin, window, scan)
        self.frontiers.update(self.costmap, changed)
        if changed[1] > changed[0]:
            self._frontier_changed = True
            self.planner.map_changed()  # plans kept only while the costmap stays the same
        self._map_updated = True
        if self.local is None:
            self.local = LocalCostmap(self.params, resolution)
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
                    self.params, self.local, self.dwa, pose, self.safety.check(t, ranges, 0.0),
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
            if t - g.plan_fail_since >= self.params.planner_patience:
                self._give_up(t, "no plan")
            return NavCommand(0.0, 0.0, "planning")
        return self._drive(t, pose, v0, w0, ranges)

    def _drive(self, t: float, pose: np.ndarray, v0: float, w0: float, ranges) -> NavCommand:
        """Follow the plan: the door passage through a tight door ahead (door_align), the
        heading shim when the plan lies behind, else the DWA; the safety controller has the
        last word on the DWA's and the door passage's forward commands."""
        g = self.pursuit
        if self.params.trap_reach > 0.0:
            out = self.trail.closed_behind(self.local, self.params.trap_reach)
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
            if self.params.door_align or g.goal.squeeze
            else None
        )
        if shim is None:
            shim = self.shim.command(pose, w0, g.path, self.local)
        if shim is not None:
            self._command_found()
            if self._no_progress(t, pose):
                self._give_up(t, "no progress", pose)
                return NavCommand(0.0, 0.0, "recovering")
            if shim[2] == "door":
                # the door passage judges its motions on the SLAM map; what the laser sees
                # in front of the robot (a chair leg the map lacks, a jamb the pose's error
                # hides) is the safety controller's to veto, as for the DWA's commands
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
        cmd = self._dwa_command(pose, v0, w0)
        if cmd.kind == "aligned":
            self._finish(t, "reached")
            return NavCommand(0.0, 0.0, "aligning")
        if not cmd.legal:
            vw = unwedge(self.params, self.local, self.costmap, pose)
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
        vw = safe_override(self.params, self.local, self.dwa, pose, override, v0, w0, planned)
        return NavCommand(*vw, "safety")

    def _dwa_command(self, pose: np.ndarray, v0: float, w0: float) -> Command:
        """The DWA's command; with nothing legal, its command on the scans alone."""
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
        return cmd

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
            self.pursuit is not None
            and self._frontier_changed
            and not self.frontiers.frontier_near(
                self.costmap, self.pursuit.goal.frontier_xy, self.params.blacklist_radius
            )
        ):
            self._finish(t, "explored")
        self._frontier_changed = False

    def _choose(self, t: float, pose: np.ndarray) -> None:
        """Choose the frontier: keep the goal, switch to a clearly nearer one, or drop it."""
        p = self.params
        mem = self.memory
        self._next_choice_t = t + p.frontier_period
        new = self.frontiers.choose(self.costmap, pose[:2], mem.blacklist, mem.avoid())
        # before giving up on the building, give the blacklisted frontiers (and the closed
        # gaps) another chance
        if new is None and mem.retry():
            self.closed.clear()
            new = self.frontiers.choose(self.costmap, pose[:2], mem.blacklist)
        if new is None:
            new = self._look_through(pose)
        if new is None:
            new = self._squeeze(pose)
        if new is None and len(self.closed.points) and self._reopens_left > 0:
            # nothing left with the closed gaps closed: one of them may seal the robot in (a
            # room it entered through a gap it then failed to leave by): open them once
            self._reopens_left -= 1
            self.closed.clear()
            new = self.frontiers.choose(self.costmap, pose[:2], mem.blacklist, mem.avoid())
            if new is None:
                new = self._look_through(pose)
            if new is None:
                new = self._squeeze(pose)
        g = self.pursuit
        if new is None:
            if g is not None:
                self._end_goal(t, "dropped", "no reachable frontier left")
            self._enter(NavState.EXHAUSTED)
            return
        if g is not None:
            if np.hypot(*(new.goal_xy - g.goal.goal_xy)) <= p.same_goal_distance:
                return  # same goal, keep its plan and progress timers
            # Switch only to a clearly nearer frontier: two about equally near ones must not
            # make the robot dither between them.
            remaining = path_length(g.path) / self.costmap.resolution * p.neutral_cost
            if g.path is None or new.travel_cost >= p.goal_switch_ratio * remaining:
                return
            self._end_goal(t, "replaced", "a nearer frontier")
        # the frontier search's own path: the first plan
        next_plan_t = t + 1.0 / p.planner_frequency
        self.pursuit = Pursuit(new, t, new.path_xy, next_plan_t, progress_t=t)
        self.door.new_goal()
        self.dwa.set_plan(new.path_xy)
        self._enter(NavState.DRIVING)

    def _look_through(self, pose: np.ndarray) -> FrontierGoal | None:
        """The last pass: a goal that looks at a frontier through a gap the robot cannot
        pass (`FrontierSearch.choose`, look_through), or None (or off)."""
        if self.params.look_through_radius <= 0.0:
            return None
        mem = self.memory
        return self.frontiers.choose(
            self.costmap, pose[:2], mem.looked, mem.avoid(), look_through=True
        )

    def _squeeze(self, pose: np.ndarray) -> FrontierGoal | None:
        """The last pass, after the look-through pass: a frontier behind a gap only
        squeeze_margin lets through (`FrontierSearch.choose`, squeeze), or None (or off).
        Last, because a robot that slipped in through such a door may not line up with it
        again from inside, and everything still to explore elsewhere would be lost."""
        mem = self.memory
        return self.frontiers.choose(
            self.costmap, pose[:2], mem.blacklist, mem.avoid(), squeeze=True
        )

    def _plan(self, t: float, pose: np.ndarray) -> None:
        g = self.pursuit
        g.next_plan_t = t + 1.0 / self.params.planner_frequency
        path = self.planner.plan(self.costmap, pose[:2], g.goal.goal_xy, g.goal.squeeze)
        if path is None:
            self.stats.plan_failures += 1
            if g.plan_fail_since is None:
                g.plan_fail_since = t
            g.next_plan_t = t + 1.0 / self.params.controller_frequency
        else:
            g.plan_fail_since = None
        g.path = path
        self.dwa.set_plan(path)
        if path is None or self.state is NavState.PLANNING:
            self._enter(self._goal_layer_state())

    def _controller_failed(self, t: float, pose: np.ndarray) -> NavCommand:
        """move_base: no legal command -> clear the local costmap and replan; later give up."""
        g = self.pursuit
        if g.ctrl_fail_since is None:
            g.ctrl_fail_since = t
        self._enter(NavState.RECOVERING)
        elapsed = t - g.ctrl_fail_since
        if elapsed >= self.params.controller_patience:
            self._give_up(t, "no legal command", pose)
        elif not self._recovered and elapsed >= self.params.recovery_delay:
            self._recovered = True
            self.stats.recoveries += 1
            self.local.clear()
            g.next_plan_t = t  # replan now
            self._start_retrace(t, pose)
        return NavCommand(0.0, 0.0, "recovering")

    def _no_progress(self, t: float, pose: np.ndarray) -> bool:
        """explore_lite's progress_timeout: the goal got no nearer for too long, neither in a
        straight line (explore_lite's measure) nor along the plan. The plan may lead away
        from the goal first, round a block of rooms and through doors taken slowly; a robot
        driving along it makes progress (office_d_furnitures, oracle, 0.1 m noise, seed 7:
        a room's door given up at 950 s after 35 s of steady driving on a detour, the room
        never entered)."""
        g = self.pursuit
        step = self.params.progress_step
        gap = float(np.hypot(*(g.goal.goal_xy - pose[:2])))
        route = remaining_length(g.path, pose[:2])
        if gap < g.best_gap - step:
            g.best_gap = gap
            g.progress_t = t
        if route < g.best_route - step:
            g.best_route = route
            g.progress_t = t
        return t - g.progress_t >= self.params.progress_timeout

    def _finish(self, t: float, status: str) -> None:
        """Goal done. A frontier still there after the robot arrived is approached from
        elsewhere next time, and blacklisted after blacklist_arrivals such arrivals (the SLAM
        map updates only after some motion, so one arrival is not enough to tell)."""
        p = self.params
        goal = self.pursuit.goal
        f, r = goal.frontier_xy, p.blacklist_radius
        if status == "reached" and self.frontiers.frontier_near(self.costmap, f, r):
            self.memory.arrived(f, goal.goal_xy, r, p.blacklist_arrivals, goal.look_through)
        self.stats.consecutive_failures = 0
        self._end_goal(t, status)

    def _start_retrace(self, t: float, pose: np.ndarray | None = None, target=None) -> None:
        """Recovery: back out along the way the robot came (that space was free), to
        `target` (a trail point; default `Trail.back_target`)."""
        if target is None:
            target = self.trail.back_target(None if pose is None else pose[:2])
        if target is None:
            return
        self.retrace = Retrace(target, t + self.params.retrace_time)
        self.stats.recoveries += 1
        self._enter(NavState.RETRACING)

    def _retrace(self, t: float, pose: np.ndarray) -> tuple[float, float] | None:
        """Reverse towards the retrace point; None: done (or blocked), back to the goal layer."""
        d = self.retrace.target - pose[:2]
        vw = None
        if np.hypot(*d) < self.params.retrace_tolerance or t >= self.retrace.until:
            self.trail.cut_to(self.retrace.target)
        else:
            aim = self.retrace.target
            if self.params.retrace_lookahead > 0.0:
                aim = self.trail.carrot(pose[:2], aim, self.params.retrace_lookahead)
            vw = back_out(self.params, self.local, pose, aim - pose[:2])
        if vw is None:
            self.retrace = None
            self._enter(self._goal_layer_state())
        return vw

    def _give_up(self, t: float, why: str, pose: np.ndarray | None = None, out=None) -> None:
        """The goal given up: back out, blacklist its frontier; when the robot could not get
        on (no progress, no legal command) with its plan through a gap under the planner's
        margin near it, close that gap to the narrow fallback (`ClosedGaps`)."""
        g = self.pursuit
        if pose is not None and g.path is not None:
            self.closed.close(
                self.costmap, self.params, g.path, pose[:2], self.params.closed_gap_radius
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
