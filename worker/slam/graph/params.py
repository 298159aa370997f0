"""GraphSlamParams: the graph SLAM settings, named after slam_toolbox / Cartographer, with units."""

from __future__ import annotations

import math
from dataclasses import dataclass

from worker.errors import InputError


@dataclass(frozen=True)
class GraphSlamParams:
    """Parameters of the pose-graph SLAM (`worker.slam.graph.slam.GraphSlam`).

    Defaults are slam_toolbox's (mapper_params_online_async.yaml) where it has the setting and
    Cartographer's (2D trajectory builder, constraint builder) where the matcher follows it.
    The map resolution, beam limits and occupancy threshold come from SlamParams (delta,
    max_urange, max_range, occ_thresh), as for every algorithm.
    """

    # front end: a node when the robot moved this far since the last node
    minimum_travel_distance: float = 0.5  # [m] slam_toolbox minimum_travel_distance
    minimum_travel_heading: float = 0.5  # [rad] slam_toolbox minimum_travel_heading
    scan_buffer_size: int = 10  # [nodes] recent scans in the local map (slam_toolbox 10)
    scan_buffer_maximum_scan_distance: float = 10.0  # [m] slam_toolbox, 10
    point_spacing: float = 0.05  # [m] scan points closer than this to the previous are dropped
    # (Cartographer's voxel_filter_size 0.025 at 5 cm cells: one point per cell or so)
    match_range: float = 15.0  # [m] beams longer than this are not used for matching
    # correlative scan matching against the local map (centred on the odometry prior)
    correlation_search_space_dimension: float = 0.5  # [m] full width (slam_toolbox 0.5)
    correlation_search_space_smear_deviation: float = 0.1  # [m] slam_toolbox 0.1
    coarse_search_angle_offset: float = 0.349  # [rad] +- window (slam_toolbox 0.349)
    # Karto's penalties for leaving the odometry prior: response * max(minimum, 1 - 0.2 d^2 / var)
    distance_variance_penalty: float = 0.5  # [m^2] slam_toolbox 0.5
    angle_variance_penalty: float = 1.0  # [rad^2] slam_toolbox 1.0
    minimum_distance_penalty: float = 0.5  # slam_toolbox 0.5
    minimum_angle_penalty: float = 0.9  # slam_toolbox 0.9
    link_match_minimum_response_fine: float = 0.1  # below it the odometry edge alone (slam_toolbox)
    branch_and_bound_depth: int = (
        5  # pyramid levels above the map (Cartographer: 7 local, 8 global)
    )
    # the front end's pose: the match fused with the odometry's prediction by their
    # information (the ICP's J^T J against the odometry sigmas below), so that what the walls
    # leave free (a corridor's length, a flat response) follows the odometry, as
    # Cartographer's Ceres scan matcher weighs the predicted pose (translation_weight,
    # rotation_weight); off: the match alone, held only by Karto's penalties
    odometry_fusion: bool = True
    # innovation gate on the front end's match: a match farther from the odometry's
    # prediction than this chi^2 (3 dof; 16.27 = 0.999) under the odometry sigmas below is
    # an optimum the odometry rules out (a scan fitted turned by 0.28 rad in a room whose
    # walls allow it, drawing a wall across a door); the scan is matched again within
    # sqrt(chi^2) sigmas of the prediction, and that match is taken when it scores at least
    # loop_ambiguity_ratio (0.9) of the first (else the scan's evidence stands). 0: off
    link_gate_chi2: float = 16.27
    # edges' standard deviations (Karto derives them from the match response; fixed here)
    match_sigma_xy: float = 0.05  # [m] of a scan-match edge
    match_sigma_theta: float = 0.02  # [rad]
    odom_sigma_xy_per_m: float = 0.1  # [m/m] of an odometry-only edge, per metre moved
    odom_sigma_theta_per_rad: float = 0.1  # [rad/rad], per radian turned (+ 0.01 rad floor)
    # loop closure
    do_loop_closing: bool = True  # slam_toolbox do_loop_closing
    loop_search_maximum_distance: float = 3.0  # [m] candidates this close (slam_toolbox 3.0)
    loop_match_minimum_chain_size: int = 10  # [nodes] slam_toolbox 10
    loop_search_space_dimension: float = 8.0  # [m] full width of the search (slam_toolbox 8.0)
    loop_search_space_smear_deviation: float = 0.03  # [m] slam_toolbox 0.03
    loop_angular_search_window: float = 0.524  # [rad] +- (Cartographer constraint builder: 30 deg)
    # slam_toolbox accepts 0.45; Cartographer 0.55 (constraint_builder min_score): corridor
    # shifts of a chain that saw only part of the place reach 0.47 here, true closures 0.7-0.97
    loop_match_minimum_response_fine: float = 0.55
    # the minimum response of a closure that moves the robot to the edge of its search
    # window (the drift the path since the candidate allows): the bar rises from
    # loop_match_minimum_response_fine with the square of the correction's share of the
    # window (`nodes.loop_min_score`), so that a weak match may not pull the robot where the
    # drift nearly rules it out (a like room 3.6 m off in a +-3.9 m window in
    # office_b_furnitures seed 2 at 0.571; true closures of the real logs correct up to 0.43
    # of their window, at 0.553-0.64). Cartographer asks 0.6 of a search without a prior
    # (global_localization_min_score) where a windowed one needs 0.55 (min_score)
    loop_match_minimum_response_wide: float = 0.6
    loop_branch_and_bound_depth: int = 7  # Cartographer's constraint builder: 7
    # a loop match whose scan points face the candidate's points the other way (normals
    # turned toward the sensor) in more than this share of their pairs within 0.1 m (at
    # least 10 pairs) is refused: it fitted the other face of a wall (office_a_furnitures
    # seed 1: 0.97-0.98 in three such closures; its true ones in the first 300 s 0-0.02,
    # those of the three real logs at seed 0 up to 0.13). 1: off
    loop_max_opposed_share: float = 0.5
    # ambiguity check (the role of Karto's loop_match_maximum_variance_coarse): the best match
    # farther than loop_ambiguity_radius from the found one must score below this share of it,
    # or the place is ambiguous (a corridor, a twin room) and no closure is made
    loop_ambiguity_radius: float = 0.5  # [m]
    loop_ambiguity_ratio: float = 0.9
    # an ambiguous match whose rival is the same rotation shifted (a corridor: the scan
    # slides along it) still fixes the rotation and the offset across the shift: it is
    # added with loop_corridor_sigma along the shift instead of being dropped (what Karto's
    # match covariance does); rivals turned by more than loop_corridor_max_rotation are not
    loop_corridor_sigma: float = 1.0  # [m] along the shift (about free); 0 drops them all
    loop_corridor_max_rotation: float = 0.02  # [rad]
    # the closure checked the other way round: the candidate's scan matched against the
    # nodes leading to the current one must land where the closure puts it (within
    # loop_ambiguity_radius and loop_gate_theta), or the closure is not made
    loop_reverse_check: bool = True
    loop_attempt_every: int = 3  # [nodes] a loop search every this many nodes (Cartographer
    # samples 0.3 of the nodes for constraints: sampling_ratio 0.3)
    # a closure that moves the current node less than this is added without optimising at
    # once (the graph hardly changes); the next larger one optimises with all of them
    loop_optimize_min_correction: float = 0.03  # [m]
    loop_optimize_min_rotation: float = 0.01  # [rad]
    # consistency check: the correction a closure implies must be within what the odometry
    # could have drifted along the path since the candidate (a gate on the chain's uncertainty)
    loop_gate_xy: float = 0.3  # [m] floor of the gate
    # [m/m] plus this per metre of path between the two nodes: 3 % of the way, an odometry's
    # drift (the front end, fused with the odometry, drifts at most as the odometry where the
    # walls leave a direction free; less elsewhere). 0.1 until c7a071a: wide
    # enough for a like room 2-3.5 m away to close in lab_a_scan and office_b_furnitures
    loop_gate_xy_per_m: float = 0.03
    loop_gate_theta: float = 0.1  # [rad] floor
    loop_gate_theta_per_m: float = 0.02  # [rad/m]
    loop_sigma_xy: float = 0.05  # [m] of a loop edge
    loop_sigma_theta: float = 0.02  # [rad]
    huber_delta: float = 1.0  # [sigma] Huber kernel on loop edges (slam_toolbox's Ceres HuberLoss)
    loop_max_chi2: float = 16.27  # a closure whose edge keeps more than this (chi^2 3 dof, 0.999)
    # after optimisation is undone: it disagrees with the rest of the graph
    # the map is rebuilt when an optimisation moved a node past these since it was drawn
    map_rebuild_tolerance_xy: float = 0.025  # [m] half a 5 cm cell
    map_rebuild_tolerance_theta: float = 0.0025  # [rad] half a cell at 10 m
    # back end (Levenberg-Marquardt, slam_toolbox's Ceres solver)
    optimizer_iterations: int = 20
    optimizer_tolerance: float = 1e-6  # stop when the cost falls by less than this fraction
    # offline only (the final trajectory; the online estimate never sees it): Cartographer's
    # final optimisation, run when an offline trajectory is finished (cartographer_ros's
    # offline node): each node matched again, as the front end matches, against the nodes on
    # both sides at their settled poses, the links between consecutive nodes replaced by
    # these matches, and the graph optimised again (worker.slam.graph.final)
    # Off by default: on the three CARMEN logs (bench_graph_carmen, seeds 0-2) it moved the
    # mean B error by -0.009 to -0.011 m on Freiburg 079 but by -0.005 to +0.007 m on ACES
    # and CSAIL, no general gain there (on 30-minute simulated logs, with exact ground truth,
    # it cut it by 0-38 %, for 40 % more CPU; figures in the commit that added it)
    run_final_optimization: bool = False
    final_scan_buffer_size: int = 5  # [nodes] each side: a map as large as the front end's
    # (scan_buffer_size 10), half of it from after the node
    max_num_final_iterations: int = 200  # Cartographer POSE_GRAPH.max_num_final_iterations

    def __post_init__(self) -> None:
        positive = (
            "minimum_travel_distance", "minimum_travel_heading",
            "scan_buffer_maximum_scan_distance", "point_spacing", "match_range",
            "correlation_search_space_dimension",
            "correlation_search_space_smear_deviation", "coarse_search_angle_offset",
            "match_sigma_xy", "match_sigma_theta", "distance_variance_penalty",
            "angle_variance_penalty", "odom_sigma_xy_per_m",
            "odom_sigma_theta_per_rad", "loop_search_maximum_distance",
            "loop_search_space_dimension", "loop_search_space_smear_deviation",
            "loop_angular_search_window", "loop_ambiguity_radius", "loop_optimize_min_correction",
            "loop_optimize_min_rotation", "map_rebuild_tolerance_xy",
            "map_rebuild_tolerance_theta", "loop_gate_xy",
            "loop_gate_theta", "loop_sigma_xy",
            "loop_sigma_theta", "huber_delta", "loop_max_chi2", "optimizer_tolerance",
        )  # fmt: skip
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"graph parameter {name} must be a positive number, got {value}")
        for name in ("loop_gate_xy_per_m", "loop_gate_theta_per_m", "loop_corridor_sigma",
                     "loop_corridor_max_rotation", "link_gate_chi2"):  # fmt: skip
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"graph parameter {name} must be >= 0, got {value}")
        unit = (
            "link_match_minimum_response_fine", "loop_match_minimum_response_fine",
            "loop_match_minimum_response_wide", "loop_max_opposed_share",
            "minimum_distance_penalty", "minimum_angle_penalty", "loop_ambiguity_ratio",
        )  # fmt: skip
        for name in unit:
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise InputError(f"graph parameter {name} must be in [0, 1]")
        if self.loop_match_minimum_response_wide < self.loop_match_minimum_response_fine:
            raise InputError(
                "graph parameter loop_match_minimum_response_wide must be at least "
                "loop_match_minimum_response_fine"
            )
        counts = {
            "scan_buffer_size": (1, 1000),
            "loop_match_minimum_chain_size": (1, 1000),
            "branch_and_bound_depth": (0, 10),
            "loop_branch_and_bound_depth": (0, 10),
            "loop_attempt_every": (1, 1000),
            "optimizer_iterations": (1, 1000),
            "final_scan_buffer_size": (1, 1000),
            "max_num_final_iterations": (1, 10000),
        }
        for name, (lo, hi) in counts.items():
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise InputError(f"graph parameter {name} must be in [{lo}, {hi}], got {value}")
