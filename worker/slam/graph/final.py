"""The offline final optimisation (Cartographer's PoseGraph::RunFinalOptimization, run when an
offline trajectory is finished): once the graph has settled, every node's scan is matched
again against its neighbours on both sides at their optimised poses, and the front-end edges
between consecutive nodes, each made when only the nodes before the newer one existed, are
replaced by the relative poses of these matches; the graph is then optimised again. A node
whose own front-end match went wrong is placed by the map of the nodes around it, so the
wrong match is outvoted instead of being carried by both its edges."""

from __future__ import annotations

import numpy as np

from worker.slam.graph.optimize import Edges
from worker.slam.keyposes import relative_many


def two_sided_nodes(poses: np.ndarray, k: int, per_side: int, max_dist: float) -> np.ndarray:
    """(K,) int64 the nodes up to `per_side` before and after node k (not k itself) whose
    poses (N, 3) lie within max_dist [m] of node k's."""
    n = poses.shape[0]
    idx = np.concatenate(
        [np.arange(max(0, k - per_side), k), np.arange(k + 1, min(n, k + per_side + 1))]
    ).astype(np.int64)
    d = np.hypot(poses[idx, 0] - poses[k, 0], poses[idx, 1] - poses[k, 1])
    return idx[d <= max_dist]


def relink_edges(
    edges: Edges, matched: np.ndarray, pose_match: np.ndarray, sigma: tuple[float, float, float]
) -> Edges:
    """`edges` with each front-end link (not robust, from node i to i + 1) whose two nodes
    were both matched again (matched (N,) bool) replaced by the relative pose of their
    matches pose_match (N, 3), with standard deviations sigma [m, m, rad]; loop edges and the
    links of a node whose match failed are kept as they were."""
    link = ~edges.robust & (edges.j == edges.i + 1)
    swap = link & matched[edges.i] & matched[edges.j]
    z, s = edges.z.copy(), edges.sigma.copy()
    z[swap] = relative_many(pose_match[edges.i[swap]], pose_match[edges.j[swap]])
    s[swap] = sigma
    # the links were made with zero frames; only loop edges (kept) have turned axes
    return Edges(edges.i, edges.j, z, s, edges.robust, edges.frame)
