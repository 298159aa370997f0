"""GraphSlam: Karto / slam_toolbox-style pose-graph SLAM behind the Slam protocol."""

from __future__ import annotations

import math

import numpy as np

from worker.slam.base import LaserGeometry, beam_angles, beam_limits
from worker.slam.gating import UpdateGate, check_scan
from worker.slam.graph.final import relink_edges, two_sided_nodes
from worker.slam.graph.mapping import NodeMap, scan_reach
from worker.slam.graph.match_kernels import point_normals, scan_points
from worker.slam.graph.matcher import MatchResult, opposed_share, point_map_around, prior_chi2
from worker.slam.graph.nodes import (
    EdgeList,
    LoopClosure,
    NodeStore,
    find_candidate,
    loop_min_score,
    search_window,
    shift_direction,
)
from worker.slam.graph.optimize import edge_errors, optimize
from worker.slam.graph.params import GraphSlamParams
from worker.slam.grid import OccupancyGrid
from worker.slam.keyposes import ScanTrack
from worker.slam.motion import compose3, relative3
from worker.slam.params import SlamParams

NORMAL_GAP = 0.3  # [m] scan points farther apart are not neighbours when estimating normals
OPPOSED_RADIUS = 0.1  # [m] a loop match's scan point and a map point this close are a pair
OPPOSED_MIN_PAIRS = 10  # fewer pairs are no evidence of a wall's other face


class GraphSlam:
    """A node every minimum_travel_distance / heading; each matched against a local map of
    the recent nodes (correlative search around the odometry prior) and tied to the previous
    node by the match (or by odometry alone when the match is poor). Every loop_attempt_every
    nodes an earlier chain near the estimate is searched for a loop closure; an accepted one
    adds a robust edge and the graph is optimised. The estimate is the latest node's optimised
    pose composed with the odometry since; the map is rebuilt from the optimised poses.
    """

    name = "graph"

    def __init__(self, laser: LaserGeometry, params: SlamParams):
        self.params = params
        self.graph_params = params.graph if params.graph is not None else GraphSlamParams()
        g = self.graph_params
        angles = beam_angles(laser)
        self._n_beams = angles.shape[0]
        self._cos_a, self._sin_a = np.cos(angles), np.sin(angles)
        self._max_range, self._usable = beam_limits(laser, params)
        self._match_max = min(g.match_range, self._usable)
        self._gate = UpdateGate(g.minimum_travel_distance, g.minimum_travel_heading, -1.0)
        self.nodes = NodeStore(self._n_beams)
        self.edges = EdgeList()
        self.map = NodeMap(
            params.delta, params.map_margin, params.occ_thresh,
            self._cos_a, self._sin_a, self._usable, self._max_range,
            (g.map_rebuild_tolerance_xy, g.map_rebuild_tolerance_theta),
        )  # fmt: skip
        self.closures: list[LoopClosure] = []
        self.rejected_closures = 0  # matched, then undone by the chi^2 check
        self.reverse_rejected_closures = 0  # matched, but the reverse match put it elsewhere
        self.ambiguous_closures = 0  # matched, but as well somewhere else
        self.corridor_closures = 0  # ambiguous along one shift only: added, free along it
        self.match_failures = 0  # nodes tied by odometry alone
        self.weak_far_closures = 0  # loop matches too weak for how far they move the robot
        self.opposed_closures = 0  # loop matches onto the other face of a wall
        self.gated_matches = 0  # front-end optima the odometry ruled out (matched again)
        self.optimisations = 0
        self.updates = 0
        self._pose_odom = np.zeros(3)
        self._T_map_odom = np.zeros(3)
        self._grid: OccupancyGrid | None = None
        self._scans = ScanTrack()  # per scan processed: odometry, path so far, latest node
        # ((nodes, edges) counts, (N, 3) poses) of the last final optimisation
        self._final: tuple[tuple[int, int], np.ndarray] | None = None
        self.final_matched = 0  # nodes the final optimisation matched again

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        t, pose, ranges = check_scan(t, pose_odom, ranges_m, self._n_beams)
        self._pose_odom = pose
        self._scans.scan(pose)
        if not self._gate.step(t, pose):
            return False
        k = self._add_node(t, pose, ranges)
        self._scans.keyed(k)
        g = self.graph_params
        if g.do_loop_closing and k % g.loop_attempt_every == 0:
            self._try_loop_closure(k)
        self._T_map_odom = compose3(self.nodes.poses[k], _inverse3(pose))
        self.updates += 1
        self._grid = None
        return True

    def _add_node(self, t: float, pose_odom: np.ndarray, ranges: np.ndarray) -> int:
        g, nodes = self.graph_params, self.nodes
        pts = scan_points(ranges, self._cos_a, self._sin_a, self._match_max, g.point_spacing)
        nrm = point_normals(pts, NORMAL_GAP)
        reach = scan_reach(ranges, self._usable, self._max_range)
        if nodes.n == 0:  # the map frame is the odometry frame of the first scan
            return nodes.add(pose_odom, pose_odom, t, self._scans.path_m, ranges, pts, nrm, reach)
        prev = nodes.n - 1
        odo = relative3(nodes.odom[prev], pose_odom)
        prior = compose3(nodes.poses[prev], odo)
        odo_sigma = self._odometry_sigma(odo)
        info = np.diag(1.0 / np.square(odo_sigma)) if g.odometry_fusion else None
        local = self._local_nodes(prev, prior)
        match = self._link_match(local, pts, prior, None, info)
        gate = g.link_gate_chi2
        if (
            gate > 0
            and match.score >= g.link_match_minimum_response_fine
            and prior_chi2(match.pose, prior, odo_sigma) > gate
        ):
            # the odometry rules this optimum out: the best match it allows instead, if
            # the scan fits there nearly as well (else the scan's evidence wins). The
            # search window is a box: first the one around the gate's ellipsoid
            # (+-sqrt(chi^2) sigma), then, if its best is still outside the gate (a room
            # that fits turned 0.23 rad and 0.12 m off, each within its axis's bound),
            # the one inside it (+-sqrt(chi^2 / 3) sigma)
            for reach in (math.sqrt(gate), math.sqrt(gate / 3.0)):
                window = (reach * odo_sigma[0], reach * odo_sigma[2])
                near = self._link_match(local, pts, prior, None, info, window)
                if prior_chi2(near.pose, prior, odo_sigma) <= gate:
                    break
            if near.score >= g.loop_ambiguity_ratio * match.score:
                self.gated_matches += 1
                match = near
        if match.score >= g.link_match_minimum_response_fine:
            pose = match.pose
            z = relative3(nodes.poses[prev], pose)
            sigma = (g.match_sigma_xy, g.match_sigma_xy, g.match_sigma_theta)
        else:
            self.match_failures += 1
            pose, z, sigma = prior, odo, odo_sigma
        k = nodes.add(pose, pose_odom, t, self._scans.path_m, ranges, pts, nrm, reach)
        self.edges.add(prev, k, z, sigma, robust=False)
        return k

    def _odometry_sigma(self, odo: np.ndarray) -> tuple[float, float, float]:
        """[m, m, rad] the odometry's standard deviations over the step `odo` (3,): in x and y
        odom_sigma_xy_per_m of the way (at least 0.01 m), in heading 0.01 rad plus
        odom_sigma_theta_per_rad of the turn."""
        g = self.graph_params
        s_xy = max(0.01, g.odom_sigma_xy_per_m * math.hypot(odo[0], odo[1]))
        return (s_xy, s_xy, 0.01 + g.odom_sigma_theta_per_rad * abs(odo[2]))

    def _local_nodes(self, last: int, prior: np.ndarray) -> np.ndarray:
        """(K,) the last scan_buffer_size nodes up to `last` within
        scan_buffer_maximum_scan_distance of the prior (and `last` always)."""
        g, nodes = self.graph_params, self.nodes
        idx = np.arange(max(0, last - g.scan_buffer_size + 1), last + 1)
        d = np.hypot(nodes.poses[idx, 0] - prior[0], nodes.poses[idx, 1] - prior[1])
        return idx[(d <= g.scan_buffer_maximum_scan_distance) | (idx == last)]

    def _link_match(
        self,
        idx: np.ndarray,
        points: np.ndarray,
        prior: np.ndarray,
        poses: np.ndarray | None = None,
        prior_information: np.ndarray | None = None,
        window: tuple[float, float] | None = None,
    ) -> MatchResult:
        """The front end's match of scan `points` (M, 2) [robot frame] near `prior` (3,)
        against the smeared map of nodes `idx` placed at `poses` (N, 3) (None: the nodes'
        current poses), cut to what the scan can reach: the correlative window around the
        prior with Karto's penalties for leaving it; with `prior_information` (3, 3) the
        result is fused with the prior (`PointMap.match`). window: (+-[m], +-[rad]) narrower
        than the correlative search's own (each is capped by it)."""
        g, nodes = self.graph_params, self.nodes
        pts, nrm = nodes.map_points(idx, poses)
        reach = self._match_max + 0.5 * g.correlation_search_space_dimension
        point_map = point_map_around(
            pts, nrm, prior, reach, self.params.delta,
            g.correlation_search_space_smear_deviation, g.branch_and_bound_depth,
        )  # fmt: skip
        lin, ang = 0.5 * g.correlation_search_space_dimension, g.coarse_search_angle_offset
        if window is not None:
            lin, ang = min(lin, window[0]), min(ang, window[1])
        return point_map.match(
            points,
            prior,
            lin,
            ang,
            g.link_match_minimum_response_fine,
            (g.distance_variance_penalty, g.minimum_distance_penalty),
            (g.angle_variance_penalty, g.minimum_angle_penalty),
            prior_information=prior_information,
        )

    def _try_loop_closure(self, k: int) -> None:
        g, nodes = self.graph_params, self.nodes
        cand = find_candidate(nodes.poses[: nodes.n], nodes.path_m[: nodes.n], k, g)
        if cand is None:
            return
        # the drift since the two nodes were last tied together: along the graph's shortest
        # path (earlier closures shorten it), at most along the way driven
        path = min(cand.path_m, self.edges.graph_distance(nodes.n, cand.node, k, cand.path_m))
        lin, ang = search_window(path, g)
        cur = nodes.poses[k].copy()
        chain_map = self._loop_map(cand.chain, cur, lin)
        min_score = g.loop_match_minimum_response_fine
        match = chain_map.match(nodes.points[k], cur, lin, ang, min_score)
        if match.score < min_score:
            return
        correction = math.hypot(match.pose[0] - cur[0], match.pose[1] - cur[1])
        if match.score < loop_min_score(correction, lin, g):
            self.weak_far_closures += 1
            return
        if g.loop_max_opposed_share < 1.0:
            share, pairs = opposed_share(
                chain_map, nodes.points[k], nodes.normals[k], match.pose, OPPOSED_RADIUS
            )
            if pairs >= OPPOSED_MIN_PAIRS and share > g.loop_max_opposed_share:
                self.opposed_closures += 1
                return
        excl = (float(match.pose[0]), float(match.pose[1]), g.loop_ambiguity_radius)
        rival_bar = g.loop_ambiguity_ratio * match.score  # a rival below the bar is none
        other = chain_map.match(nodes.points[k], cur, lin, ang, rival_bar, exclude=excl)
        sigma = (g.loop_sigma_xy, g.loop_sigma_xy, g.loop_sigma_theta)
        frame = 0.0
        if other.score >= rival_bar:
            frame = shift_direction(match.pose, other.pose, g.loop_corridor_max_rotation)
            if frame is None or g.loop_corridor_sigma <= 0:
                self.ambiguous_closures += 1
                return
            self.corridor_closures += 1
            sigma = (g.loop_corridor_sigma, g.loop_sigma_xy, g.loop_sigma_theta)
        if g.loop_reverse_check and not self._reverse_agrees(
            k, cand.node, cur, match.pose, lin, ang
        ):
            self.reverse_rejected_closures += 1
            return
        z = relative3(nodes.poses[cand.node], match.pose)
        self.edges.add(cand.node, k, z, sigma, robust=True, frame=frame)
        moved = relative3(cur, match.pose)
        small = (
            math.hypot(moved[0], moved[1]) < g.loop_optimize_min_correction
            and abs(moved[2]) < g.loop_optimize_min_rotation
        )
        if not self._optimise_and_check(optimise=not small):
            self.edges.pop()
            self.rejected_closures += 1
            return
        self.closures.append(
            LoopClosure(k, cand.node, float(nodes.t[k]), match.score, cur, nodes.poses[k].copy())
        )

    def _loop_map(self, idx: np.ndarray, centre: np.ndarray, lin: float):
        """The loop closure's map of nodes `idx` (smeared finely, Cartographer's deeper
        pyramid), cut to what a scan matched within +-lin [m] of `centre` (3,) can reach."""
        g = self.graph_params
        pts, nrm = self.nodes.map_points(idx)
        return point_map_around(
            pts, nrm, centre, self._match_max + lin, self.params.delta,
            g.loop_search_space_smear_deviation, g.loop_branch_and_bound_depth,
        )  # fmt: skip

    def _reverse_agrees(
        self, k: int, cand: int, cur: np.ndarray, pose: np.ndarray, lin: float, ang: float
    ) -> bool:
        """The closure checked the other way round: the candidate node's scan matched against
        the map of the nodes leading to node k (as many as a candidate's chain), around where
        the closure puts it (node k at its estimate `cur`, the candidate where the closure's
        relative pose `pose` says). False when that match finds a better place for it farther
        than loop_ambiguity_radius or loop_gate_theta from there: the two scans then agree on
        a different relative pose than the one found, as when the current scan saw mostly
        what the candidate's chain never saw and fitted a like wall elsewhere. A reverse match
        below the minimum response (the recent nodes saw too little of the candidate's place)
        is no evidence either way."""
        g, nodes = self.graph_params, self.nodes
        expected = compose3(cur, relative3(pose, nodes.poses[cand]))
        recent = np.arange(max(0, k - g.loop_match_minimum_chain_size), k + 1)
        recent_map = self._loop_map(recent, expected, lin)
        min_score = g.loop_match_minimum_response_fine
        back = recent_map.match(nodes.points[cand], expected, lin, ang, min_score)
        if back.score < min_score:
            return True
        off = relative3(expected, back.pose)
        return (
            math.hypot(off[0], off[1]) <= g.loop_ambiguity_radius
            and abs(off[2]) <= g.loop_gate_theta
        )

    def _optimise_and_check(self, optimise: bool) -> bool:
        """Optimise with the newest (loop) edge (or not, for a small correction); keep the
        result only if that edge's chi^2 stays under loop_max_chi2 (it agrees with the rest
        of the graph)."""
        g, nodes = self.graph_params, self.nodes
        edges = self.edges.arrays()
        poses = nodes.poses[: nodes.n]
        if optimise:
            poses = optimize(
                poses, edges, g.huber_delta, g.optimizer_iterations, g.optimizer_tolerance
            ).poses
            self.optimisations += 1
        err, _, _ = edge_errors(poses, edges)
        if float((err[-1] ** 2).sum()) > g.loop_max_chi2:
            return False
        nodes.poses[: nodes.n] = poses
        return True

    def final_trajectory(self) -> np.ndarray:
        """(N, 3) the pose at every scan processed so far as the final graph has it (offline
        SLAM's answer; pose_estimate gave the online one, before later closures). A node's
        scan is at its optimised pose (`final_node_poses`); a scan between nodes a and b at
        the two poses the odometry gives from each, (P_a (+) o_a^-1 o_s) and
        (P_b (+) o_b^-1 o_s), blended by the share of the odometry path from a to b travelled
        at the scan; scans after the last node from it alone."""
        n = self.nodes.n
        return self._scans.trajectory(
            self.final_node_poses(), self.nodes.odom[:n], self.nodes.path_m[:n]
        )

    def final_node_poses(self) -> np.ndarray:
        """(N, 3) the nodes' poses after the offline final optimisation (worker.slam.graph.final;
        the online ones with run_final_optimization off). Computed once per state of the
        graph (it changes only in `process`); the online graph, and the map `occupancy`
        draws from it, are left as they are."""
        key = (self.nodes.n, len(self.edges))
        if self._final is None or self._final[0] != key:
            self._final = (key, self._final_optimisation())
        return self._final[1].copy()

    def _final_optimisation(self) -> np.ndarray:
        g, nodes = self.graph_params, self.nodes
        n = nodes.n
        poses = nodes.poses[:n].copy()
        self.final_matched = 0
        if not g.run_final_optimization or n < 2:
            return poses
        matched = np.zeros(n, dtype=bool)
        pose_match = poses.copy()
        for k in range(n):
            idx = two_sided_nodes(
                poses, k, g.final_scan_buffer_size, g.scan_buffer_maximum_scan_distance
            )
            if idx.size == 0:
                continue
            match = self._link_match(idx, nodes.points[k], poses[k], poses)
            if match.score >= g.link_match_minimum_response_fine:
                matched[k], pose_match[k] = True, match.pose
        self.final_matched = int(matched.sum())
        sigma = (g.match_sigma_xy, g.match_sigma_xy, g.match_sigma_theta)
        edges = relink_edges(self.edges.arrays(), matched, pose_match, sigma)
        return optimize(
            poses, edges, g.huber_delta, g.max_num_final_iterations, g.optimizer_tolerance
        ).poses

    def pose_estimate(self) -> np.ndarray:
        return compose3(self._T_map_odom, self._pose_odom)

    def T_map_odom(self) -> np.ndarray:
        return self._T_map_odom.copy()

    def node_poses(self) -> np.ndarray:
        """(N, 3) [x, y, theta] the nodes' current (optimised) poses."""
        return self.nodes.poses[: self.nodes.n].copy()

    def final_occupancy(self) -> OccupancyGrid:
        """The map drawn at `final_node_poses` (offline SLAM's map, beside `final_trajectory`);
        with run_final_optimization off, the online map itself."""
        if not self.graph_params.run_final_optimization:
            return self.occupancy()
        n = self.nodes.n
        final = NodeMap(
            self.params.delta, self.params.map_margin, self.params.occ_thresh,
            self._cos_a, self._sin_a, self._usable, self._max_range,
        )  # fmt: skip
        if n:
            final.update(self.final_node_poses(), self.nodes.ranges[:n], self.nodes.reach[:n])
        return final.occupancy()

    def occupancy(self) -> OccupancyGrid:
        # incremental while the poses stay; a closure moved them: rebuilt from every node
        if self._grid is None:
            n = self.nodes.n
            if n:
                self.map.update(self.nodes.poses[:n], self.nodes.ranges[:n], self.nodes.reach[:n])
            self._grid = self.map.occupancy()
        return self._grid

    def occupancy_with_hits(self) -> OccupancyGrid:
        """`occupancy` with its cells' end-point counts (for the map score; not cached)."""
        self.occupancy()  # brings the map up to the nodes' poses
        return self.map.occupancy(with_hits=True)


def _inverse3(a: np.ndarray) -> np.ndarray:
    c, s = math.cos(a[2]), math.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]])
