"""The pose graph: nodes (poses, odometry, scans) and edges in growing arrays, and the loop
closure candidates among the nodes: earlier nodes near the current estimate but away from
the recent chain (Karto's FindPossibleLoopClosure), with the search window the odometry's
drift allows."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from worker.slam.graph.optimize import Edges
from worker.slam.graph.params import GraphSlamParams


class NodeStore:
    """Per node: pose (map frame), odometry pose, time, path length [m], ranges, scan points
    (robot frame, for matching) and reach [m]; grown by doubling."""

    def __init__(self, n_beams: int):
        self.n = 0
        cap = 64
        self.poses = np.zeros((cap, 3))  # (N, 3) [x, y, theta] map frame, optimised
        self.odom = np.zeros((cap, 3))  # (N, 3) odometry pose at the node
        self.t = np.zeros(cap)  # [s]
        self.path_m = np.zeros(cap)  # [m] odometry path length from the first node
        self.reach = np.zeros(cap)  # [m]
        self.ranges = np.zeros((cap, n_beams), dtype=np.float32)
        self.points: list[np.ndarray] = []  # (M, 2) [m] robot frame
        self.normals: list[np.ndarray] = []  # (M, 2) unit normals of the points, robot frame

    def add(
        self, pose, odom, t: float, path_m: float, ranges, points, normals, reach: float
    ) -> int:
        """Append a node; its index."""
        if self.n == self.poses.shape[0]:
            for name in ("poses", "odom", "t", "path_m", "reach", "ranges"):
                arr = getattr(self, name)
                grown = np.zeros((2 * arr.shape[0],) + arr.shape[1:], dtype=arr.dtype)
                grown[: self.n] = arr[: self.n]
                setattr(self, name, grown)
        k = self.n
        self.poses[k], self.odom[k], self.t[k] = pose, odom, t
        self.path_m[k], self.reach[k], self.ranges[k] = path_m, reach, ranges
        self.points.append(points)
        self.normals.append(normals)
        self.n += 1
        return k

    def map_points(
        self, idx: np.ndarray, poses: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(K, 2) [m] the scan points of nodes `idx` placed at `poses` (N, 3) (None: their
        current poses), and their normals (K, 2) in the map frame."""
        poses = self.poses if poses is None else poses
        out, nrm = [], []
        for k in idx:
            xy, n = place(poses[k], self.points[k], self.normals[k])
            out.append(xy)
            nrm.append(n)
        if not out:
            return np.zeros((0, 2)), np.zeros((0, 2))
        return np.concatenate(out), np.concatenate(nrm)


def place(
    pose: np.ndarray, points: np.ndarray, normals: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Scan points (M, 2) [m] and their normals (M, 2), robot frame, placed at `pose` (3,):
    (points, normals) in the map frame."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    xy = np.column_stack([pose[0] + c * points[:, 0] - s * points[:, 1],
                          pose[1] + s * points[:, 0] + c * points[:, 1]])  # fmt: skip
    nrm = np.column_stack([c * normals[:, 0] - s * normals[:, 1],
                           s * normals[:, 0] + c * normals[:, 1]])  # fmt: skip
    return xy, nrm


class EdgeList:
    """Constraints appended one by one; `arrays()` for the optimiser."""

    def __init__(self) -> None:
        self.i: list[int] = []
        self.j: list[int] = []
        self.z: list[np.ndarray] = []
        self.sigma: list[tuple[float, float, float]] = []
        self.robust: list[bool] = []
        self.frame: list[float] = []

    def add(self, i: int, j: int, z: np.ndarray, sigma, robust: bool, frame: float = 0.0) -> None:
        """z: (3,) pose of j in i's frame; sigma: (3,) [m, m, rad] along axes turned by
        frame [rad] from z's frame."""
        self.i.append(i)
        self.j.append(j)
        self.z.append(np.asarray(z, dtype=np.float64))
        self.sigma.append(tuple(sigma))
        self.robust.append(robust)
        self.frame.append(float(frame))

    def pop(self) -> None:
        """Drop the last edge."""
        for lst in (self.i, self.j, self.z, self.sigma, self.robust, self.frame):
            lst.pop()

    def __len__(self) -> int:
        return len(self.i)

    def graph_distance(self, n: int, src: int, dst: int, limit: float) -> float:
        """Shortest distance [m] from node src to node dst through the graph's edges, each
        as long as the translation it measures; corridor closures (sigma along the corridor
        differs from across) are left out, since they do not fix that direction. inf when
        farther than `limit` [m]. Once loop closures tie the path back, the odometry drift
        that separates two nodes is that of this path, not of the whole way driven."""
        if not self.i:
            return math.inf
        e = self.arrays()
        keep = e.sigma[:, 0] == e.sigma[:, 1]
        # explicit zeros would be read as no edge: a node that did not move is 1 um away
        w = np.hypot(e.z[keep, 0], e.z[keep, 1]) + 1e-6
        graph = csr_matrix((w, (e.i[keep], e.j[keep])), shape=(n, n))
        d = dijkstra(graph, directed=False, indices=src, limit=limit)
        return float(d[dst])

    def arrays(self) -> Edges:
        """The edges as arrays."""
        return Edges(
            np.array(self.i, dtype=np.int64),
            np.array(self.j, dtype=np.int64),
            np.array(self.z).reshape(-1, 3),
            np.array(self.sigma, dtype=np.float64).reshape(-1, 3),
            np.array(self.robust, dtype=bool),
            np.array(self.frame, dtype=np.float64),
        )


@dataclass(frozen=True)
class LoopCandidate:
    """The earlier node nearest the current one, its chain (node indices), the path [m]."""

    node: int
    chain: np.ndarray  # (K,) int64 node indices around `node`, all before the recent chain
    path_m: float  # [m] odometry path length from `node` to the current node


@dataclass(frozen=True)
class LoopClosure:
    """An accepted closure: current node, candidate node, response, poses before / after."""

    node: int
    candidate: int
    t: float  # [s] time of the current node
    score: float
    pose_before: np.ndarray  # (3,) the current node's estimate before the closure
    pose_after: np.ndarray  # (3,) after the optimisation


def recent_chain_start(poses: np.ndarray, cur: int, radius: float) -> int:
    """First index of the run of nodes ending at `cur` that all lie within `radius` [m] of
    it: the recent chain, which the front end already ties to the current node."""
    d = np.hypot(poses[:cur, 0] - poses[cur, 0], poses[:cur, 1] - poses[cur, 1])
    far = np.flatnonzero(d > radius)
    return int(far[-1]) + 1 if far.size else 0


def find_candidate(
    poses: np.ndarray, path_m: np.ndarray, cur: int, g: GraphSlamParams
) -> LoopCandidate | None:
    """The earlier node nearest node `cur` within loop_search_maximum_distance, outside the
    recent chain, with a chain of at least loop_match_minimum_chain_size nodes around it."""
    start = recent_chain_start(poses, cur, g.loop_search_maximum_distance)
    if start < g.loop_match_minimum_chain_size:
        return None
    d = np.hypot(poses[:start, 0] - poses[cur, 0], poses[:start, 1] - poses[cur, 1])
    near = np.flatnonzero(d <= g.loop_search_maximum_distance)
    if near.size == 0:
        return None
    c = int(near[np.argmin(d[near])])
    half = g.loop_match_minimum_chain_size // 2
    lo = max(0, c - half)
    hi = min(start, lo + 2 * half + 1)
    lo = max(0, hi - 2 * half - 1)
    chain = np.arange(lo, hi, dtype=np.int64)
    if chain.size < g.loop_match_minimum_chain_size:
        return None
    return LoopCandidate(c, chain, float(path_m[cur] - path_m[c]))


def search_window(path_m: float, g: GraphSlamParams) -> tuple[float, float]:
    """(+-linear [m], +-angular [rad]) the closure may correct: what the odometry could drift
    along path_m, capped by slam_toolbox's / Cartographer's search windows. A place that looks
    the same farther away than this (an identical room next door) is never matched."""
    lin = min(0.5 * g.loop_search_space_dimension, g.loop_gate_xy + g.loop_gate_xy_per_m * path_m)
    ang = min(g.loop_angular_search_window, g.loop_gate_theta + g.loop_gate_theta_per_m * path_m)
    return lin, ang


def loop_min_score(correction: float, lin: float, g: GraphSlamParams) -> float:
    """The response a loop match must reach when it moves the current node `correction` [m]
    in a search of +-lin [m] (the drift the path allows): the drift is a prior on the
    correction, and a weak match may not pull the robot to where that prior rules it
    nearly out. From loop_match_minimum_response_fine at no correction up to
    loop_match_minimum_response_wide at the window's edge, with the square of the
    correction's share of the window (the log of a Gaussian prior, as Karto's penalties
    on leaving the odometry)."""
    share = 1.0 if lin <= 0 else min(1.0, (correction / lin) ** 2)
    fine, wide = g.loop_match_minimum_response_fine, g.loop_match_minimum_response_wide
    return fine + share * (wide - fine)


def shift_direction(pose: np.ndarray, rival: np.ndarray, max_rotation: float) -> float | None:
    """[rad] the direction from a match's pose to its rival's, in the match's frame (the
    axis a corridor leaves free), or None when the rival is turned by more than
    max_rotation [rad]: not a shift."""
    if abs(math.remainder(float(rival[2] - pose[2]), 2.0 * math.pi)) > max_rotation:
        return None
    return math.atan2(rival[1] - pose[1], rival[0] - pose[0]) - float(pose[2])
