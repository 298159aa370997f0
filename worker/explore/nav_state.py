"""The navigator's states, the transitions between them and the data each state carries."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from worker.explore.frontiers import FrontierGoal
from worker.explore.planner import remaining_length


class NavState(Enum):
    """What the navigation stack is doing (`Navigator.state`).

    SAFETY and RETRACING take over from the goal layer for a while; the goal layer's states
    (IDLE to RECOVERING) share one step: end the goal if its frontier vanished, re-choose the
    frontier when due, replan when due, then drive. Their data is the `Pursuit` (none in
    IDLE and EXHAUSTED).
    """

    WAITING = "waiting"  # no SLAM map yet: stand still
    IDLE = "idle"  # no goal: the next step chooses a frontier
    EXHAUSTED = "exhausted"  # no reachable frontier left (the loop ends the run if it stays)
    PLANNING = "planning"  # a goal and no plan to it: the planner fails (Pursuit.plan_fail_since)
    DRIVING = "driving"  # following the plan: the heading shim or the DWA
    ESCAPING = "escaping"  # the footprint touches an obstacle: the motion that gets it out
    RECOVERING = "recovering"  # no legal command (Pursuit.ctrl_fail_since): wait, clear, replan
    RETRACING = "retracing"  # backing out along the trail (`Retrace`)
    SAFETY = "safety"  # the safety controller's back-off (its data: SafetyController)


_S = NavState
_ENDS_GOAL = "the goal ended (reached, explored, replaced, dropped, or given up)"
_GIVES_UP_AND_BACKS_OUT = "the goal given up: back out along the trail"
_GOAL_LAYER = {
    _S.DRIVING: "a goal chosen (the frontier search's path is its first plan), or a plan found",
    _S.PLANNING: "the planner found no path to the goal",
    _S.EXHAUSTED: "no reachable frontier left",
}
# (state -> {next state: why}): every change of `Navigator.state`, each for one reason
TRANSITIONS: dict[NavState, dict[NavState, str]] = {
    _S.WAITING: {_S.IDLE: "the first SLAM map came"},
    _S.IDLE: {
        _S.DRIVING: _GOAL_LAYER[_S.DRIVING],
        _S.EXHAUSTED: _GOAL_LAYER[_S.EXHAUSTED],
    },
    _S.EXHAUSTED: {
        _S.DRIVING: "a frontier came up (the map changed, or the blacklist was cleared)",
    },
    _S.PLANNING: {
        _S.DRIVING: "the planner found a path",
        _S.RECOVERING: "the planner found a path, the controller still failing since before",
        _S.IDLE: _ENDS_GOAL,
        _S.RETRACING: _GIVES_UP_AND_BACKS_OUT,
    },
    _S.DRIVING: {
        _S.PLANNING: _GOAL_LAYER[_S.PLANNING],
        _S.IDLE: _ENDS_GOAL,
        _S.ESCAPING: "no legal command, the footprint touching an obstacle",
        _S.RECOVERING: "no legal command",
        _S.RETRACING: _GIVES_UP_AND_BACKS_OUT,
        _S.SAFETY: "an obstacle too near in front",
    },
    _S.ESCAPING: {
        _S.DRIVING: "a legal command again (or the heading shim turns)",
        _S.PLANNING: _GOAL_LAYER[_S.PLANNING],
        _S.IDLE: _ENDS_GOAL,
        _S.RECOVERING: "no legal command, and no way out of the contact",
        _S.RETRACING: _GIVES_UP_AND_BACKS_OUT,
    },
    _S.RECOVERING: {
        _S.DRIVING: "a legal command again (or the heading shim turns)",
        _S.PLANNING: _GOAL_LAYER[_S.PLANNING],
        _S.IDLE: _ENDS_GOAL,
        _S.ESCAPING: "still no legal command, the footprint touching an obstacle",
        _S.RETRACING: "recovery_delay without a legal command (or the goal given up)",
    },
    _S.RETRACING: {
        _S.IDLE: "back out done (or blocked), no goal",
        _S.RECOVERING: "back out done (or blocked), the goal still on",
    },
    _S.SAFETY: {_S.DRIVING: "the back-off is over"},
}


@dataclass
class Pursuit:
    """The goal being pursued, its plan and its timers (map frame)."""

    goal: FrontierGoal
    t0: float  # [s] when it was chosen
    path: np.ndarray | None  # (K, 2) [x, y] the plan being followed; None: no plan (PLANNING)
    next_plan_t: float  # [s] when to replan
    progress_t: float  # [s] when the goal last got progress_step nearer
    best_gap: float = math.inf  # [m] the nearest the robot has been to the goal
    best_route: float = math.inf  # [m] the shortest rest of the plan from the robot so far
    plan_fail_since: float | None = None  # [s] the planner failing since (PLANNING)
    ctrl_fail_since: float | None = None  # [s] no legal command since (RECOVERING)

    def no_progress(self, t: float, pose: np.ndarray, step: float, timeout: float) -> bool:
        """explore_lite's progress_timeout: the goal got no `step` [m] nearer for `timeout`
        [s], neither in a straight line (explore_lite's measure) nor along the plan. The plan
        may lead away from the goal first, round a block of rooms and through doors taken
        slowly; a robot driving along it makes progress (office_d_furnitures, oracle, 0.1 m
        noise, seed 7: a room's door given up at 950 s after 35 s of steady driving on a
        detour, the room never entered)."""
        gap = float(np.hypot(*(self.goal.goal_xy - pose[:2])))
        route = remaining_length(self.path, pose[:2])
        if gap < self.best_gap - step:
            self.best_gap = gap
            self.progress_t = t
        if route < self.best_route - step:
            self.best_route = route
            self.progress_t = t
        return t - self.progress_t >= timeout


@dataclass(frozen=True)
class Retrace:
    """RETRACING: backing out towards a point of the trail, until a time at the latest."""

    target: np.ndarray  # (2,) [m] map frame
    until: float  # [s]


@dataclass
class FrontierMemory:
    """What the goal choice remembers across goals: frontiers to leave alone."""

    retries: int  # times the blacklist may still be cleared when nothing else is left
    blacklist: list[np.ndarray] = field(default_factory=list)  # (2,) [m] frontiers given up
    # (frontier, goal) of goals reached whose frontier did not vanish
    arrived_at: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    # (2,) [m] frontiers the look-through pass gave up (its own blacklist: the frontiers it
    # looks at are those whose goals beyond a narrow door failed, on the blacklist above)
    looked: list[np.ndarray] = field(default_factory=list)
    # (2,) [m] frontier cells the robot arrived at blacklist_arrivals times without them going
    # away: those near them are left alone, the rest of their cluster is not. A viewpoint
    # can fail where another does not: in a hall wider than the laser's range, beams with no
    # return clear nothing, and the sector they span stays unknown until the robot looks
    # from where they reach a wall
    spent: list[np.ndarray] = field(default_factory=list)

    def avoid(self) -> list[np.ndarray]:
        """Goals already reached without their frontier going away: look from elsewhere."""
        return [g for _, g in self.arrived_at]

    def retry(self) -> bool:
        """Forget the blacklist, the arrivals and the spent frontier cells, if retries are
        left; True when it did."""
        if not (self.blacklist or self.spent) or self.retries <= 0:
            return False
        self.retries -= 1
        self.blacklist.clear()
        self.spent.clear()
        self.arrived_at.clear()
        return True

    def arrived(
        self, frontier_xy: np.ndarray, goal_xy: np.ndarray, radius: float, n: int,
        look_through: bool = False,
    ):  # fmt: skip
        """A goal reached with its frontier still there: next time a goal elsewhere near it;
        after n arrivals within 2 radius (the two blacklist discs overlap), leave the frontier
        cells near it alone (`spent`; for a look-through goal, its frontier is looked at)."""
        self.arrived_at.append((frontier_xy.copy(), goal_xy.copy()))
        if sum(np.hypot(*(frontier_xy - q)) <= 2 * radius for q, _ in self.arrived_at) >= n:
            (self.looked if look_through else self.spent).append(frontier_xy.copy())

    def give_up(self, frontier_xy: np.ndarray, look_through: bool = False) -> None:
        """Leave this frontier alone: blacklisted, or for a look-through goal, looked at."""
        (self.looked if look_through else self.blacklist).append(frontier_xy.copy())


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
    recoveries: int = 0  # local costmap clearings + back-outs after the controller failed
    plan_failures: int = 0
    consecutive_failures: int = 0  # given-up goals since the last success
    transitions: Counter[tuple[NavState, NavState]] = field(default_factory=Counter)


def grown_box(box, pose: np.ndarray, ranges, angles: np.ndarray):
    """`box (x0, y0, x1, y1)` [m] (None: none yet) grown to hold the robot at `pose` and its
    beams' end points."""
    a = angles + pose[2]
    xs = pose[0] + ranges * np.cos(a)
    ys = pose[1] + ranges * np.sin(a)
    new = (
        min(xs.min(), pose[0]), min(ys.min(), pose[1]),
        max(xs.max(), pose[0]), max(ys.max(), pose[1]),
    )  # fmt: skip
    if box is None:
        return new
    return (min(box[0], new[0]), min(box[1], new[1]), max(box[2], new[2]), max(box[3], new[3]))
