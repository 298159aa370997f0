"""ExploreParams: the navigation stack's settings, with the thesis's ROS values as defaults."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field, fields
from typing import Literal, get_args

from worker.errors import InputError
from worker.sim.params import FOOTPRINT_M

SnapshotMeasure = Literal["changed_share", "mse"]  # ExploreParams.snapshot_measure
SNAPSHOT_MEASURES: tuple[str, ...] = get_args(SnapshotMeasure)


@dataclass(frozen=True)
class ExploreParams:
    """Exploration settings; defaults are the thesis's (Sec. 6.2) or the ROS packages' own.

    Serialisable with `dataclasses.asdict`; read user values with `worker.params.from_dict`.
    """

    # --- robot and costmaps (costmap_2d; thesis pioneer3at_costmap_common_params) ---
    # [m] half side of the square footprint: derived from the robot's one size setting,
    # SimParams.footprint, by RunParams (`with_footprint`); not a parameter of its own
    footprint_half_m: float = field(default=0.5 * FOOTPRINT_M, init=False)
    # [m] added to the half side in the local planner's collision test (ROS footprint_padding;
    # the thesis had 0: ours covers the 2.5 cm between trajectory samples)
    footprint_padding: float = 0.02
    inflation_radius: float = 2.25  # [m] inflation_layer.inflation_radius
    cost_scaling_factor: float = 7.5  # [1/m] inflation_layer.cost_scaling_factor
    occupied_thresh: float = 0.25  # [-] SLAM cell probability from which a cell is an obstacle
    # obstacle layer (thesis pioneer3at_costmap_common_params): the latest scan marks its hits
    # within obstacle_range lethal (wall faces the SLAM map shows free under its occupied
    # threshold) and clears, by raytracing up to raytrace_range, the marks its beams cross;
    # readings without a return are dropped
    obstacle_layer: bool = True
    obstacle_range: float = 30.0  # [m]
    raytrace_range: float = 30.0  # [m]
    # [-] the obstacle layer's marks count only in cells the SLAM map does not know as
    # firmly free (probability at least this, or unknown); 0: everywhere
    obstacle_min_prob: float = 0.0
    # on a laser with range noise (sim.laser_noise_sigma > 0; `for_range_noise`) the stack
    # takes the door passage (door_align) and counts the obstacle layer's marks only where
    # the SLAM map is not firmly free (obstacle_min_prob at least this): one scan's noisy
    # hits at a door's jambs close it to the planner and the DWA, where the map, made of
    # many scans, holds it open (docs/results/laser-noise.md). A noise-free laser's runs do not
    # change.
    noisy_door_align: bool = True
    noisy_obstacle_min_prob: float = 0.1
    global_costmap_rate: float = 2.0  # [Hz] global_costmap.update_frequency
    full_map_check_period: float = 30.0  # [s] whole-map re-read (catches SLAM map switches)
    growth_margin: float = 10.0  # [m] the costmap grows by this much when the map outgrows it
    local_window_m: float = 6.0  # [m] local_costmap width = height (rolling window)
    local_persistence: float = 1.0  # [s] how long scan obstacles stay in the local costmap
    # each scan clears the earlier scans' marks in the cells its beams cross (costmap_2d's
    # raytrace clearing): a noisy short reading lasts until the next beam through it
    local_raytrace: bool = True
    # --- frontiers (explore_lite) ---
    min_frontier_size: float = 0.5  # [m] clusters smaller than this are ignored
    # [m^2] unknown regions up to this size enclosed by known cells (the inside of table legs,
    # of walls) are not worth a frontier: no viewpoint reveals them
    min_unknown_area: float = 0.5
    # a frontier cell the robot looked at this many times from within dead_frontier_radius
    # (in view, in line of sight) and that stayed frontier is dead: what lies beyond it is
    # the inside of an obstacle whose face the beams only glanced off
    dead_frontier_looks: int = 6
    dead_frontier_radius: float = 1.0  # [m]
    # [rad] a look counts within the laser's field of view less this (its edge beams graze)
    look_fov_margin: float = 0.05
    goal_radius: float = 0.6  # [m] goal search radius around the frontier (goal back-off)
    # [goal radii] the search travels this much past the first candidate cell, so that the goal
    # can be the lowest-cost cell of that cluster, not its nearest edge
    goal_search_extra: float = 2.0
    sight_candidates: int = 64  # goal candidates tested for a line of sight to their frontier
    frontier_period: float = 5.0  # [s] re-choose the frontier this often
    blacklist_radius: float = 0.5  # [m] frontier cells this near a failed goal are ignored
    blacklist_retries: int = 1  # times the blacklist is cleared when nothing else is left
    # [m] when no frontier is left that a goal within goal_radius reaches, goals up to this
    # far from a frontier that see it: a look through a door too narrow to pass into the room
    # behind it (0: off). The arrivals' rule below gives each such frontier up to
    # blacklist_arrivals viewpoints.
    look_through_radius: float = 1.5
    # [m^2] ... at a frontier next to unknown space larger than this (a room, not the unseen
    # floor under a table or between chairs, which no viewpoint in reach reveals either)
    look_through_min_area: float = 4.0
    # times the gaps closed after failures (closed_gap_radius) are opened again when nothing
    # else is left, the look-through pass included: a gap closed behind the robot must not
    # seal it in a room for the rest of the run
    closed_gap_reopens: int = 1
    # arrivals near a frontier that stays there (goals "reached" within 2 blacklist_radius of
    # it) after which it is blacklisted: the SLAM map updates only after some motion
    blacklist_arrivals: int = 3
    same_goal_distance: float = 1.0  # [m] a re-chosen goal this near is the same goal (kept)
    goal_switch_ratio: float = 0.5  # [-] switch goals when the new one costs < this x the rest
    progress_timeout: float = 30.0  # [s] a goal with no progress for this long is given up
    progress_step: float = 0.1  # [m] the goal must get this much nearer to count as progress
    # --- global planner (navfn; thesis base_local_planner_params) ---
    planner_frequency: float = 0.2  # [Hz] replanning rate (also on every goal change)
    neutral_cost: float = 50.0  # [-] navfn COST_NEUTRAL: cost of a free cell step
    cost_factor: float = 0.8  # [-] navfn COST_FACTOR: costmap value -> step cost
    allow_unknown: bool = True  # plan through unknown space
    # [m] plans keep this much farther from obstacles than the inscribed radius (navfn: 0,
    # any non-INSCRIBED cell is fine): 0.1 m is about the circumscribed radius (0.28 m), so the
    # robot can turn wherever its plan takes it (gaps between table legs are trapped otherwise)
    planner_margin: float = 0.1
    # [m] the margin when no plan or frontier is reachable with planner_margin: a door of
    # 0.7 m clear width, mapped a cell narrower each side (0.6 m, 12 cells of 5 cm), leaves
    # the robot's centre 0.3 m from the jambs' cell centres; this lets a centre 0.26 m from
    # them through, a door the map draws 11 cells (0.55 m) wide or more
    narrow_margin: float = 0.06
    # [m] the last pass's margin (after the blacklist's retry and the look-through pass):
    # navfn's own rule (0: any cell below the inscribed cost). A door the map draws 10 cells
    # (0.5 m) wide or narrower (0.25 m from the jambs' cell centres at most: a 0.5 m door,
    # the robot's 0.4 m and 5 cm each side) is entered only when nothing else is left: a
    # robot that slipped in through one may not line up with it again from inside
    # (wilbraham). Equal to narrow_margin: no such pass
    squeeze_margin: float = 0.0
    # [m] near the robot, plans may cross the margin (not the inscribed radius): a pocket the
    # map closed around the robot as it mapped obstacles better must not trap it
    escape_radius: float = 0.5
    # [m] a goal given up for no progress or no legal command with its plan through cells
    # only the narrow fallback (or an escape) allows within this of the robot: that gap is
    # closed to every plan and goal search (planner.ClosedGaps) until the blacklist is next
    # cleared
    closed_gap_radius: float = 1.0
    # [m] the same, when nothing is reachable otherwise (the robot in a pocket between table
    # legs that the map sealed as it mapped them): before a goal or the run is given up
    pocket_escape_radius: float = 1.5
    planner_patience: float = 5.0  # [s] planning may fail this long before recovery
    # [cells] largest goal pocket flooded to prove a goal walled in before the full search
    # (100 m^2 at 5 cm); only the time to find no plan depends on it, never the plans
    sealed_pocket_cells: int = 40_000
    # --- local planner (base_local_planner TrajectoryPlannerROS with dwa: true) ---
    controller_frequency: float = 10.0  # [Hz]
    max_vel_x: float = 0.85  # [m/s]
    min_vel_x: float = 0.1  # [m/s]
    max_vel_theta: float = 0.7  # [rad/s]
    min_in_place_vel_theta: float = 0.4  # [rad/s]
    acc_lim_x: float = 1.5  # [m/s^2]
    acc_lim_theta: float = 2.5  # [rad/s^2]
    escape_vel: float = -0.1  # [m/s] backing-off speed when nothing else is legal
    sim_time: float = 1.5  # [s] forward simulation horizon
    sim_granularity: float = 0.025  # [m] step between trajectory points
    angular_sim_granularity: float = 0.025  # [rad] step between trajectory points in rotation
    vx_samples: int = 10
    vtheta_samples: int = 20
    pdist_scale: float = 0.6  # weight of the distance to the global path [1/m]
    gdist_scale: float = 0.8  # weight of the distance to the local goal [1/m]
    occdist_scale: float = 0.05  # weight of the max obstacle cost along the trajectory
    heading_lookahead: float = 0.325  # [m] distances are scored this far ahead of the robot
    oscillation_reset_dist: float = 0.25  # [m] travel that clears the rotation-oscillation flags
    escape_reset_dist: float = 0.15  # [m] back-off distance before driving forwards again
    escape_reset_theta: float = 0.15  # [rad] or this much turning
    # heading shim (nav2 RotationShimController-like): turn on the spot (or back out) while
    # the path point shim_lookahead ahead lies more than shim_angle off the heading
    shim_angle: float = 1.2  # [rad]
    shim_release: float = 0.5  # [rad] the DWA takes over again below this
    shim_lookahead: float = 0.5  # [m]
    # door passage (door.DoorPass), off on a noise-free laser (it makes explorations 20 %
    # longer there, docs/results/laser-noise.md) and on with range noise (noisy_door_align): when
    # the path enters a door narrower than door_width (the SLAM map's walls on both sides)
    # within door_lookahead, the robot goes to a point on the door's axis, faces along it
    # (turning on the spot past door_angle) and drives through at door_speed
    door_align: bool = False
    door_width: float = 0.9  # [m]
    door_lookahead: float = 1.0  # [m]
    door_angle: float = 0.1  # [rad]
    door_speed: float = 0.15  # [m/s]
    # [m] a passage is a door only where the obstacles on both sides of it each extend at
    # least this far (walls, in the window the robot sees): a gap between table legs or
    # chairs is left to the DWA
    door_wall_min: float = 1.0
    # [m] the passage takes over only where the door as the DWA sees it (the local costmap:
    # the map and the laser's marks) is narrower than this; a wider one the DWA drives
    # through at speed, as it does without a noisy laser
    door_engage_width: float = 0.8
    # [s] a passage the robot gets no 0.05 m farther into for this long is given up to the
    # DWA and the recoveries while the robot pursues the same goal
    door_patience: float = 10.0
    # [m] the door passage checks its motions with the footprint's half side grown by this
    # (the SLAM pose's error against its map): a corner a few centimetres off is not a touch
    door_margin: float = 0.03
    xy_goal_tolerance: float = 0.3  # [m]
    yaw_goal_tolerance: float = 0.2  # [rad]
    controller_patience: float = 15.0  # [s] no legal command this long -> recovery, then give up
    # --- recovery (move_base's recovery behaviours, ours: back out along the trail) ---
    recovery_delay: float = 1.0  # [s] no legal command this long -> clear, replan, back out
    retrace_time: float = 8.0  # [s] longest back-out along the way the robot came (recovery)
    trail_spacing: float = 0.05  # [m] the trail keeps positions of the robot this far apart
    trail_cap: int = 200  # trail points kept at most; past it the oldest trail_trim are dropped
    trail_trim: int = 100
    retrace_min_points: int = 4  # a trail shorter than this: no back-out
    retrace_points: int = 16  # the back-out aims this many trail points back (0.8 m)
    retrace_tolerance: float = 0.1  # [m] the back-out ends this near its target
    # [m] trap check (recovery.Trail.closed_behind): when the map as it is now puts the
    # bare footprint on an obstacle at a pose of the last trap_reach of the way the local
    # planner drove the robot forwards, the robot gives up its goal and backs out on that
    # line at once, before it turns away from it (0: off)
    trap_reach: float = 1.0
    # [m] > 0: the back-out steers at the trail point this far back along the trail (pure
    # pursuit of the rear), round the bends of the way the robot came; 0: in a straight line
    # to its target. Off: on Liselotte1 (oracle) the robot, failing goal after goal at a
    # 0.5 m door, moved less with it and ended `stuck` at 512 s (the manual's
    # docs/results/exploration.md)
    retrace_lookahead: float = 0.0
    # [rad] the back-out reverses only while the rear points within this of its target
    retrace_max_heading_error: float = 0.6
    # backing out (the retrace, or getting room to turn) at this x escape_vel [-]; turning at
    # back_out_gain [1/s] x the heading error [rad]; each motion is collision-checked
    # back_out_check_time [s] ahead
    back_out_speed_ratio: float = 1.5
    back_out_gain: float = 1.5
    back_out_check_time: float = 0.5
    # [s] getting room to turn ranks its motions by the lowest costmap value along each one's
    # legal roll-out this far ahead, not where the checked back_out_check_time ends: a motion
    # that gains a little room at once but runs into a slot loses to backing out the way the
    # robot came
    back_out_lookahead: float = 2.0
    unwedge_time: float = 1.0  # [s] an unwedging motion (footprint in contact), checked whole
    # --- safety controller (range_proximity_safety_controller) ---
    safety_distance: float = 0.2  # [m] obstacle this near the footprint's front: back off
    safety_backoff_time: float = 1.0  # [s] duration of one back-off manoeuvre
    safety_turn_vel: float = 0.4  # [rad/s] turn away from the obstacle while backing off
    # [beams] on a laser with range noise the safety controller reads each beam as the median
    # of this many neighbouring beams (laser_filters' median filter): one noisy short reading
    # is not an obstacle, anything two beams wide still is (1: the raw readings). A noise-free
    # laser's readings are taken as they are.
    safety_median_beams: int = 3
    # --- failure rules ---
    max_goal_failures: int = 10  # consecutive given-up goals -> run aborted as `stuck`
    stuck_timeout: float = 180.0  # [s] no stuck_distance of motion for this long -> `stuck`
    stuck_distance: float = 0.5  # [m]
    slam_divergence: float = 3.0  # [m] SLAM pose this far from ground truth -> `slam_diverged`
    # --- stop rules (thesis Sec. 4.x: g, e, m) ---
    snapshot_period: float = 300.0  # [s] g: map snapshots this often
    # how two snapshots are compared (stop_rules.snapshot_change): "changed_share" stops when
    # less than snapshot_change of the known map changed class (free / occupied / unknown)
    # beyond snapshot_tolerance cells; "mse", the thesis's rule, when the pixel MSE of the
    # map_saver images is below snapshot_mse (e). The thesis's e = 5 never fires on a
    # particle filter's map, whose walls move by a cell as particles take over; the share
    # 0.01 with 1 cell fires at the end of a finished exploration and not before (the manual's
    # docs/results/exploration.md)
    snapshot_measure: SnapshotMeasure = "changed_share"
    snapshot_change: float = 0.01  # [-] share of the known map
    snapshot_tolerance: int = 1  # [cells]
    snapshot_mse: float = 5.0  # [-] e: 0..255 pixel levels squared
    # times a run the snapshot rule waits one more period because the robot is on its way
    # to a frontier it chose since the earlier snapshot (stop_rules.MapUnchangedRule): a
    # robot crossing a large building to its last rooms changes little of its map in 300 s.
    # Off until the trap check (trap_reach): without it the wait kept office_g_furnitures
    # going until the robot was stuck in a pocket at 3,513 s (the manual's
    # docs/results/exploration.md, "the end of an exploration")
    snapshot_holds: int = 1
    time_limit: float = 7200.0  # [s] m: simulated-time limit
    # [s] no reachable frontier for this long -> completed (`no_frontier`): a transient gap in
    # the map must not end the run
    no_frontier_time: float = 1.0
    # a run stopped as done is `incomplete` when the floorplan holds a reachable region never
    # seen free at least this large [m^2] and this wide [m] (a room behind a given-up frontier,
    # not the slivers along walls no viewpoint shows): the harness's judgement, not the robot's
    incomplete_area: float = 2.0
    incomplete_width: float = 0.8
    # [m] ... and when that region lies behind gaps the robot can drive through: its centre
    # keeping more than footprint_half_m + footprint_padding + this from the plan's walls (the
    # SLAM map draws each side of a door up to a cell nearer, and navfn plans only beyond the
    # inscribed radius). 0.27 m in all: a 0.7 m door of a 0.1 m plan passes, 0.6 m does not;
    # rooms behind the 0.5 m doors of Histor4 are not a given-up frontier
    incomplete_cell_loss: float = 0.05
    progress_period: float = 1.0  # [s] on_progress callback period
    coverage_period: float = 10.0  # [s] the coverage on_progress reports is refreshed this often

    def __post_init__(self) -> None:
        if self.snapshot_measure not in SNAPSHOT_MEASURES:
            raise InputError(
                f"exploration parameter snapshot_measure must be one of "
                f"{', '.join(SNAPSHOT_MEASURES)}, not {self.snapshot_measure!r}"
            )
        signed = ("escape_vel", "occdist_scale", "pdist_scale", "gdist_scale")
        may_be_zero = (
            "footprint_padding", "blacklist_retries", "planner_margin", "escape_radius",
            "look_fov_margin", "goal_search_extra", "narrow_margin", "snapshot_tolerance",
            "obstacle_min_prob", "door_margin", "noisy_obstacle_min_prob",
            "look_through_radius", "closed_gap_reopens", "snapshot_holds", "trap_reach",
            "retrace_lookahead", "squeeze_margin",
        )  # fmt: skip
        bad = []
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in signed or isinstance(value, bool | str):
                continue
            if value < 0 or (value == 0 and f.name not in may_be_zero):
                bad.append(f.name)
        if bad:
            raise InputError(f"exploration parameters must be positive: {', '.join(bad)}")
        if self.min_vel_x > self.max_vel_x:
            raise InputError("exploration parameter min_vel_x exceeds max_vel_x")
        if self.escape_vel >= 0:
            raise InputError("exploration parameter escape_vel must be negative (backwards)")
        if self.safety_median_beams % 2 == 0:
            raise InputError("exploration parameter safety_median_beams must be odd")
        if max(self.obstacle_min_prob, self.noisy_obstacle_min_prob) > 1.0:
            raise InputError("exploration parameters obstacle_min_prob and "
                             "noisy_obstacle_min_prob must be at most 1")  # fmt: skip
        if self.door_margin > 0.1:
            raise InputError("exploration parameter door_margin must be at most 0.1 m")
        if self.squeeze_margin > self.narrow_margin:
            raise InputError("exploration parameter squeeze_margin exceeds narrow_margin")
        if self.trail_trim > self.trail_cap:
            raise InputError("exploration parameter trail_trim exceeds trail_cap")

    @property
    def passable_clearance_m(self) -> float:
        """[m] centre clearance of the gaps a run must pass to be judged complete."""
        return self.footprint_half_m + self.footprint_padding + self.incomplete_cell_loss

    def for_range_noise(self, sigma: float) -> ExploreParams:
        """The settings the navigation stack drives with on a laser of range noise `sigma`
        [m]: these, or with range noise the door passage on (noisy_door_align), the
        obstacle layer's marks kept out of firmly free cells (noisy_obstacle_min_prob), and
        no squeeze pass (the narrow fallback at squeeze_margin at once): a noisy map draws
        doors narrower (0.85 m doors 0.45-0.55 m between the scattered hits of the jambs),
        and the door passage, on for every goal, takes the robot through them."""
        if sigma <= 0.0:
            return self
        out = dataclasses.replace(
            self,
            door_align=self.door_align or self.noisy_door_align,
            obstacle_min_prob=max(self.obstacle_min_prob, self.noisy_obstacle_min_prob),
            narrow_margin=min(self.narrow_margin, self.squeeze_margin),
        )
        object.__setattr__(out, "footprint_half_m", self.footprint_half_m)
        return out

    def with_footprint(self, side_m: float) -> ExploreParams:
        """These settings for a square robot footprint of side `side_m` [m]."""
        out = dataclasses.replace(self)
        object.__setattr__(out, "footprint_half_m", 0.5 * side_m)
        return out
