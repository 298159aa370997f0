"""ExploreParams: the navigation stack's settings, grouped by the part that reads them, with
the thesis's ROS values as defaults (the reasons behind the values: docs/explanation/
exploration-parameters.md)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Any, Literal, get_args

from worker.errors import InputError
from worker.sim.params import FOOTPRINT_M

SnapshotMeasure = Literal["changed_share", "mse"]  # StopParams.snapshot_measure
SNAPSHOT_MEASURES: tuple[str, ...] = get_args(SnapshotMeasure)


def _check_positive(
    obj: Any, signed: tuple[str, ...] = (), may_be_zero: tuple[str, ...] = ()
) -> None:
    """InputError naming the numeric fields of `obj` below zero, or at zero unless allowed."""
    bad = []
    for f in fields(obj):
        value = getattr(obj, f.name)
        if f.name in signed or isinstance(value, bool | str) or dataclasses.is_dataclass(value):
            continue
        if value < 0 or (value == 0 and f.name not in may_be_zero):
            bad.append(f.name)
    if bad:
        raise InputError(f"exploration parameters must be positive: {', '.join(bad)}")


@dataclass(frozen=True)
class CostmapParams:
    """The robot's footprint and the costmaps (costmap_2d; thesis
    pioneer3at_costmap_common_params). Read by the global and local costmaps, the loop (update
    rates), and for the footprint by every part that tests a pose or motion for collision."""

    # [m] half side of the square footprint: derived from the robot's one size setting,
    # SimParams.footprint (RunParams.from_json fills it in, RunParams refuses another value);
    # not a parameter of its own
    footprint_half_m: float = 0.5 * FOOTPRINT_M
    # [m] added to the half side in the local planner's collision test (ROS footprint_padding)
    footprint_padding: float = 0.02
    inflation_radius: float = 2.25  # [m] inflation_layer.inflation_radius
    cost_scaling_factor: float = 7.5  # [1/m] inflation_layer.cost_scaling_factor
    occupied_thresh: float = 0.25  # [-] SLAM cell probability from which a cell is an obstacle
    # obstacle layer: the latest scan marks its hits within obstacle_range lethal and clears,
    # by raytracing up to raytrace_range, the marks its beams cross
    obstacle_layer: bool = True
    obstacle_range: float = 30.0  # [m] the obstacle layer marks hits this near
    raytrace_range: float = 30.0  # [m] the obstacle layer clears along beams this far
    # [-] the obstacle layer's marks count only in cells the SLAM map does not know as
    # firmly free (probability at least this, or unknown); 0: everywhere
    obstacle_min_prob: float = 0.0
    # [-] obstacle_min_prob at least this on a laser with range noise (`for_range_noise`)
    noisy_obstacle_min_prob: float = 0.1
    global_costmap_rate: float = 2.0  # [Hz] global_costmap.update_frequency
    full_map_check_period: float = 30.0  # [s] whole-map re-read (catches SLAM map switches)
    growth_margin: float = 10.0  # [m] the costmap grows by this much when the map outgrows it
    local_window_m: float = 6.0  # [m] local_costmap width = height (rolling window)
    local_persistence: float = 1.0  # [s] how long scan obstacles stay in the local costmap
    # each scan clears the earlier scans' marks in the cells its beams cross (costmap_2d's
    # raytrace clearing)
    local_raytrace: bool = True

    def __post_init__(self) -> None:
        _check_positive(self, may_be_zero=("footprint_padding", "obstacle_min_prob",
                                           "noisy_obstacle_min_prob"))  # fmt: skip
        if max(self.obstacle_min_prob, self.noisy_obstacle_min_prob) > 1.0:
            raise InputError("exploration parameters obstacle_min_prob and "
                             "noisy_obstacle_min_prob must be at most 1")  # fmt: skip

    def with_footprint(self, side_m: float) -> CostmapParams:
        """These settings for a square robot footprint of side `side_m` [m]."""
        return dataclasses.replace(self, footprint_half_m=0.5 * side_m)


@dataclass(frozen=True)
class FrontierParams:
    """Frontier detection and goal choice (explore_lite). Read by frontiers.FrontierSearch; the
    navigator reads look_fov_margin, blacklist_radius and look_through_radius."""

    min_frontier_size: float = 0.5  # [m] clusters smaller than this are ignored
    # [m^2] unknown regions up to this size enclosed by known cells (the inside of table legs,
    # of walls) are not worth a frontier: no viewpoint reveals them
    min_unknown_area: float = 0.5
    # [-] a frontier cell looked at this many times from within dead_frontier_radius (in view,
    # in line of sight) that stayed frontier is dead (beyond it: the inside of an obstacle)
    dead_frontier_looks: int = 6
    dead_frontier_radius: float = 1.0  # [m] looks count from this near
    # [rad] a look counts within the laser's field of view less this (its edge beams graze)
    look_fov_margin: float = 0.05
    goal_radius: float = 0.6  # [m] goal search radius around the frontier (goal back-off)
    # [-] in goal radii: the search travels this much past the first candidate cell, so that
    # the goal can be the lowest-cost cell of that cluster, not its nearest edge
    goal_search_extra: float = 2.0
    sight_candidates: int = 64  # [-] goal candidates tested for a line of sight to the frontier
    blacklist_radius: float = 0.5  # [m] frontier cells this near a failed goal are ignored
    # [m] when no frontier is left that a goal within goal_radius reaches, goals up to this
    # far from a frontier that see it (a look through a door too narrow to pass); 0: off
    look_through_radius: float = 1.5
    # [m^2] ... only at a frontier next to unknown space larger than this (a room)
    look_through_min_area: float = 4.0

    def __post_init__(self) -> None:
        _check_positive(self, may_be_zero=("look_fov_margin", "goal_search_extra",
                                           "look_through_radius"))  # fmt: skip


@dataclass(frozen=True)
class NavigatorParams:
    """Goal pursuit (move_base and explore_lite's timing and give-up rules). Read by
    navigator.Navigator."""

    frontier_period: float = 5.0  # [s] re-choose the frontier this often
    blacklist_retries: int = 1  # [-] times the blacklist is cleared when nothing else is left
    # [-] times the gaps closed after failures (PlannerParams.closed_gap_radius) are opened
    # again when nothing else is left, the look-through pass included
    closed_gap_reopens: int = 1
    # [-] arrivals near a frontier that stays there (goals reached within 2 blacklist_radius of
    # it) after which it is blacklisted
    blacklist_arrivals: int = 3
    same_goal_distance: float = 1.0  # [m] a re-chosen goal this near is the same goal (kept)
    goal_switch_ratio: float = 0.5  # [-] switch goals when the new one costs < this x the rest
    progress_timeout: float = 30.0  # [s] a goal with no progress for this long is given up
    progress_step: float = 0.1  # [m] the goal must get this much nearer to count as progress
    planner_frequency: float = 0.2  # [Hz] replanning rate (also on every goal change)
    planner_patience: float = 5.0  # [s] planning may fail this long before recovery
    controller_patience: float = 15.0  # [s] no legal command this long -> recovery, then give up

    def __post_init__(self) -> None:
        _check_positive(self, may_be_zero=("blacklist_retries", "closed_gap_reopens"))


@dataclass(frozen=True)
class PlannerParams:
    """The global planner (navfn; thesis base_local_planner_params) and its fallbacks. Read by
    planner.GlobalPlanner, planner.DijkstraSearch, planner.ClosedGaps and the frontiers' goal
    search."""

    neutral_cost: float = 50.0  # [-] navfn COST_NEUTRAL: cost of a free cell step
    cost_factor: float = 0.8  # [-] navfn COST_FACTOR: costmap value -> step cost
    allow_unknown: bool = True  # plan through unknown space
    # [m] plans keep this much farther from obstacles than the inscribed radius (navfn: 0)
    planner_margin: float = 0.1
    # [m] the margin when no plan or frontier is reachable with planner_margin
    narrow_margin: float = 0.06
    # [m] the last pass's margin, when nothing else is left (0: navfn's own rule, any cell
    # below the inscribed cost); equal to narrow_margin: no such pass
    squeeze_margin: float = 0.0
    # [m] near the robot, plans may cross the margin (not the inscribed radius)
    escape_radius: float = 0.5
    # [m] a goal given up with its plan through cells only the narrow fallback (or an escape)
    # allows within this of the robot: that gap is closed to every plan and goal search until
    # the blacklist is next cleared
    closed_gap_radius: float = 1.0
    # [m] the escape radius when nothing is reachable otherwise (the robot in a pocket the map
    # sealed around it), before a goal or the run is given up
    pocket_escape_radius: float = 1.5
    # [cells] largest goal pocket flooded to prove a goal walled in before the full search;
    # only the time to find no plan depends on it, never the plans
    sealed_pocket_cells: int = 40_000

    def __post_init__(self) -> None:
        _check_positive(self, may_be_zero=("planner_margin", "escape_radius", "narrow_margin",
                                           "squeeze_margin"))  # fmt: skip
        if self.squeeze_margin > self.narrow_margin:
            raise InputError("exploration parameter squeeze_margin exceeds narrow_margin")


@dataclass(frozen=True)
class DwaParams:
    """The local planner (base_local_planner TrajectoryPlannerROS with dwa: true) and the
    heading shim in front of it. Read by dwa.DwaPlanner and shim.HeadingShim; the velocity
    limits and the control rate also by the door passage, the recoveries, the safety
    controller (escape_vel), the local costmap (its reach) and the navigator."""

    controller_frequency: float = 10.0  # [Hz] control rate
    max_vel_x: float = 0.85  # [m/s] fastest forward speed
    min_vel_x: float = 0.1  # [m/s] slowest forward speed
    max_vel_theta: float = 0.7  # [rad/s] fastest turn
    min_in_place_vel_theta: float = 0.4  # [rad/s] slowest turn on the spot
    acc_lim_x: float = 1.5  # [m/s^2] linear acceleration limit
    acc_lim_theta: float = 2.5  # [rad/s^2] angular acceleration limit
    escape_vel: float = -0.1  # [m/s] backing-off speed when nothing else is legal
    sim_time: float = 1.5  # [s] forward simulation horizon
    sim_granularity: float = 0.025  # [m] step between trajectory points
    angular_sim_granularity: float = 0.025  # [rad] step between trajectory points in rotation
    vx_samples: int = 10  # [-] linear velocity samples
    vtheta_samples: int = 20  # [-] angular velocity samples
    pdist_scale: float = 0.6  # [1/m] weight of the distance to the global path
    gdist_scale: float = 0.8  # [1/m] weight of the distance to the local goal
    occdist_scale: float = 0.05  # [-] weight of the max obstacle cost along the trajectory
    heading_lookahead: float = 0.325  # [m] distances are scored this far ahead of the robot
    oscillation_reset_dist: float = 0.25  # [m] travel that clears the rotation-oscillation flags
    escape_reset_dist: float = 0.15  # [m] back-off distance before driving forwards again
    escape_reset_theta: float = 0.15  # [rad] or this much turning
    xy_goal_tolerance: float = 0.3  # [m] a goal this near is reached
    yaw_goal_tolerance: float = 0.2  # [rad] heading tolerance at the goal
    # heading shim (nav2 RotationShimController-like): turn on the spot (or back out) while
    # the path point shim_lookahead ahead lies more than shim_angle off the heading
    shim_angle: float = 1.2  # [rad]
    shim_release: float = 0.5  # [rad] the DWA takes over again below this
    shim_lookahead: float = 0.5  # [m]

    def __post_init__(self) -> None:
        _check_positive(self, signed=("escape_vel", "occdist_scale", "pdist_scale",
                                      "gdist_scale"))  # fmt: skip
        if self.min_vel_x > self.max_vel_x:
            raise InputError("exploration parameter min_vel_x exceeds max_vel_x")
        if self.escape_vel >= 0:
            raise InputError("exploration parameter escape_vel must be negative (backwards)")


@dataclass(frozen=True)
class DoorParams:
    """The door passage (door.DoorPass): when the path enters a door narrower than door_width
    within door_lookahead, the robot goes to a point on the door's axis, faces along it and
    drives through at door_speed. Off on a noise-free laser, on with range noise
    (noisy_door_align, `ExploreParams.for_range_noise`). The navigator and the global costmap
    read door_align."""

    door_align: bool = False  # the door passage on
    noisy_door_align: bool = True  # the door passage on with a laser of range noise
    door_width: float = 0.9  # [m] a passage narrower than this is a door
    door_lookahead: float = 1.0  # [m] doors this far along the path are taken
    door_angle: float = 0.1  # [rad] turn on the spot to face the axis past this
    door_speed: float = 0.15  # [m/s] speed through the door
    # [m] a passage is a door only where the obstacles on both sides each extend at least
    # this far (walls, not table legs or chairs)
    door_wall_min: float = 1.0
    # [m] the passage takes over only where the door as the DWA sees it (the local costmap)
    # is narrower than this
    door_engage_width: float = 0.8
    # [s] a passage the robot gets no 0.05 m farther into for this long is given up for the
    # goal being pursued
    door_patience: float = 10.0
    # [m] the passage checks its motions with the footprint's half side grown by this (the
    # SLAM pose's error against its map); at most 0.1
    door_margin: float = 0.03

    def __post_init__(self) -> None:
        _check_positive(self, may_be_zero=("door_margin",))
        if self.door_margin > 0.1:
            raise InputError("exploration parameter door_margin must be at most 0.1 m")


@dataclass(frozen=True)
class RecoveryParams:
    """Recoveries (move_base's behaviours; ours back out along the trail). Read by
    recovery.Trail and the recovery motions, by the navigator (timing, retrace), by the heading
    shim (back_out_*) and by the door passage (back_out_speed_ratio)."""

    recovery_delay: float = 1.0  # [s] no legal command this long -> clear, replan, back out
    retrace_time: float = 8.0  # [s] longest back-out along the way the robot came
    trail_spacing: float = 0.05  # [m] the trail keeps positions of the robot this far apart
    trail_cap: int = 200  # [-] trail points kept at most; past it the oldest trail_trim go
    trail_trim: int = 100  # [-] trail points dropped at once
    retrace_min_points: int = 4  # [-] a trail shorter than this: no back-out
    retrace_points: int = 16  # [-] the back-out aims this many trail points back
    retrace_tolerance: float = 0.1  # [m] the back-out ends this near its target
    # [m] trap check (recovery.Trail.closed_behind): the map now puts the bare footprint on an
    # obstacle at a pose of the last trap_reach of the way driven forwards -> give up the goal
    # and back out on that line at once (0: off)
    trap_reach: float = 1.0
    # [m] > 0: the back-out steers at the trail point this far back (pure pursuit of the
    # rear); 0: in a straight line to its target
    retrace_lookahead: float = 0.0
    # [rad] the back-out reverses only while the rear points within this of its target
    retrace_max_heading_error: float = 0.6
    back_out_speed_ratio: float = 1.5  # [-] backing out at this x escape_vel
    back_out_gain: float = 1.5  # [1/s] turning rate per heading error while backing out
    back_out_check_time: float = 0.5  # [s] each back-out motion is collision-checked this far
    # [s] getting room to turn ranks its motions by the lowest costmap value along each
    # one's legal roll-out this far ahead
    back_out_lookahead: float = 2.0
    unwedge_time: float = 1.0  # [s] an unwedging motion (footprint in contact), checked whole

    def __post_init__(self) -> None:
        _check_positive(self, may_be_zero=("trap_reach", "retrace_lookahead"))
        if self.trail_trim > self.trail_cap:
            raise InputError("exploration parameter trail_trim exceeds trail_cap")


@dataclass(frozen=True)
class SafetyParams:
    """The safety controller (range_proximity_safety_controller): safety.SafetyController; the
    door passage reads safety_distance, the recoveries safety_backoff_time."""

    safety_distance: float = 0.2  # [m] obstacle this near the footprint's front: back off
    safety_backoff_time: float = 1.0  # [s] duration of one back-off manoeuvre
    safety_turn_vel: float = 0.4  # [rad/s] turn away from the obstacle while backing off
    # [beams] on a laser with range noise each beam reads as the median of this many
    # neighbouring beams (odd; 1: the raw readings); a noise-free laser's are taken as they are
    safety_median_beams: int = 3

    def __post_init__(self) -> None:
        _check_positive(self)
        if self.safety_median_beams % 2 == 0:
            raise InputError("exploration parameter safety_median_beams must be odd")


@dataclass(frozen=True)
class StopParams:
    """Stop and failure rules (thesis Sec. 4.x: g, e; stop_rules.default_rules, which gets
    ExploreParams.time_limit, the rule m, besides)."""

    max_goal_failures: int = 10  # [-] consecutive given-up goals -> run aborted as `stuck`
    stuck_timeout: float = 180.0  # [s] no stuck_distance of motion for this long -> `stuck`
    stuck_distance: float = 0.5  # [m] motion that counts against stuck_timeout
    slam_divergence: float = 3.0  # [m] SLAM pose this far from ground truth -> `slam_diverged`
    snapshot_period: float = 300.0  # [s] g: map snapshots this often
    # how two snapshots are compared: "changed_share" stops when less than snapshot_change of
    # the known map changed class beyond snapshot_tolerance cells; "mse", the thesis's rule,
    # when the pixel MSE of the map_saver images is below snapshot_mse (e)
    snapshot_measure: SnapshotMeasure = "changed_share"
    snapshot_change: float = 0.01  # [-] share of the known map
    snapshot_tolerance: int = 1  # [cells] a class change this near an equal cell is no change
    snapshot_mse: float = 5.0  # [-] e: 0..255 pixel levels squared
    # [-] times a run the snapshot rule waits one more period because the robot is on its way
    # to a frontier it chose since the earlier snapshot
    snapshot_holds: int = 1
    # [m^2] one wait more for every this much of the map known (a big building's far wings);
    # 0: snapshot_holds whatever the size. A map with less known (a 50 m x 50 m floor) keeps
    # snapshot_holds alone
    snapshot_holds_area: float = 2500.0
    # [s] no reachable frontier for this long -> completed (`no_frontier`)
    no_frontier_time: float = 1.0

    def __post_init__(self) -> None:
        if self.snapshot_measure not in SNAPSHOT_MEASURES:
            raise InputError(
                f"exploration parameter snapshot_measure must be one of "
                f"{', '.join(SNAPSHOT_MEASURES)}, not {self.snapshot_measure!r}"
            )
        _check_positive(self, may_be_zero=("snapshot_tolerance", "snapshot_holds",
                                           "snapshot_holds_area"))  # fmt: skip


@dataclass(frozen=True)
class ExploreParams:
    """Exploration settings, one group per reader; defaults are the thesis's (Sec. 6.2) or the
    ROS packages' own. The fields at this level are the loop's own (explore.Exploration): the
    run's time budget, its progress reports and the harness's judgement of the outcome.

    Serialisable with `worker.param_io.to_dict`; read user values with `worker.param_io.from_dict`
    (stored flat dicts of before the groups: `flat_params.nest_flat`).
    """

    costmap: CostmapParams = field(default_factory=CostmapParams)
    frontiers: FrontierParams = field(default_factory=FrontierParams)
    navigator: NavigatorParams = field(default_factory=NavigatorParams)
    planner: PlannerParams = field(default_factory=PlannerParams)
    dwa: DwaParams = field(default_factory=DwaParams)
    doors: DoorParams = field(default_factory=DoorParams)
    recovery: RecoveryParams = field(default_factory=RecoveryParams)
    safety: SafetyParams = field(default_factory=SafetyParams)
    stop: StopParams = field(default_factory=StopParams)
    time_limit: float = 7200.0  # [s] m: simulated-time limit
    # [m^2] a run stopped as done is `incomplete` when the floorplan holds a reachable region
    # never seen free at least this large and incomplete_width wide (the harness's judgement)
    incomplete_area: float = 2.0
    incomplete_width: float = 0.8  # [m] see incomplete_area
    # [m] ... and when that region lies behind gaps the robot can drive through: its centre
    # keeping more than footprint_half_m + footprint_padding + this from the plan's walls
    incomplete_cell_loss: float = 0.05
    progress_period: float = 1.0  # [s] on_progress callback period
    coverage_period: float = 10.0  # [s] the coverage on_progress reports is refreshed this often

    def __post_init__(self) -> None:
        _check_positive(self)

    @property
    def passable_clearance_m(self) -> float:
        """[m] centre clearance of the gaps a run must pass to be judged complete."""
        c = self.costmap
        return c.footprint_half_m + c.footprint_padding + self.incomplete_cell_loss

    def for_range_noise(self, sigma: float) -> ExploreParams:
        """The settings the navigation stack drives with on a laser of range noise `sigma`
        [m]: these, or with range noise the door passage on (noisy_door_align), the
        obstacle layer's marks kept out of firmly free cells (noisy_obstacle_min_prob), and
        no squeeze pass (the narrow fallback at squeeze_margin at once): a noisy map draws
        doors narrower, and the door passage, on for every goal, takes the robot through."""
        if sigma <= 0.0:
            return self
        c, d, pl = self.costmap, self.doors, self.planner
        prob = max(c.obstacle_min_prob, c.noisy_obstacle_min_prob)
        return dataclasses.replace(
            self,
            costmap=dataclasses.replace(c, obstacle_min_prob=prob),
            doors=dataclasses.replace(d, door_align=d.door_align or d.noisy_door_align),
            planner=dataclasses.replace(pl, narrow_margin=min(pl.narrow_margin, pl.squeeze_margin)),
        )

    def with_footprint(self, side_m: float) -> ExploreParams:
        """These settings for a square robot footprint of side `side_m` [m]."""
        return dataclasses.replace(self, costmap=self.costmap.with_footprint(side_m))
