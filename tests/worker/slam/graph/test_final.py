"""The offline final optimisation: a node whose front-end match was wrong is put back by its
neighbours on both sides, and the online estimate never sees the step."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.slam.helpers import Laser, box_scan
from worker.evaluate.se2 import relative, wrap_angle
from worker.slam.graph.final import relink_edges, two_sided_nodes
from worker.slam.graph.optimize import Edges, optimize
from worker.slam.graph.params import GraphSlamParams
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

LASER = Laser()
BOX = (0.0, 0.0, 8.0, 5.0)  # [m] an 8 x 5 m room: its four walls fix x, y and the heading


def _drive() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """t (N,), true poses (N, 3) and ranges (N, B): 5.5 m along the room in 0.1 m steps,
    weaving a little so that the nodes are not on one line; the odometry is exact."""
    x = np.arange(1.2, 6.75, 0.1)
    pose = np.column_stack([x, 2.2 + 0.3 * np.sin(x), 0.3 * np.cos(x)])
    ranges = np.array([box_scan(p, LASER.angles, BOX) for p in pose])
    return 0.1 * np.arange(len(x)), pose, ranges


def _feed(graph: GraphSlamParams, final_every: int = 0):
    """The graph SLAM after the drive, and its online estimate at every scan; final_every > 0
    asks for the final trajectory every that many scans on the way."""
    t, pose, ranges = _drive()
    slam = make_slam("graph", LASER, SlamParams(graph=graph))
    est = np.empty_like(pose)
    for k in range(len(t)):
        slam.process(t[k], pose[k], ranges[k])
        est[k] = slam.pose_estimate()
        if final_every and k % final_every == 0:
            slam.final_trajectory()
    return slam, est, t, pose


def _mis_register(slam, k: int, offset: np.ndarray) -> tuple[np.ndarray, list]:
    """Node k put at its pose (+) offset with both its links made to agree, as a front-end
    match gone wrong leaves it: the link into k carries the wrong pose, and the next node,
    matched right against a map of mostly other nodes, is linked relative to it. What
    `_restore` needs: its pose before (3,) and its links' (index, z) before."""
    nodes, edges = slam.nodes, slam.edges
    true_k = nodes.poses[k].copy()
    c, s = np.cos(true_k[2]), np.sin(true_k[2])
    wrong = true_k + np.array([c * offset[0] - s * offset[1], s * offset[0] + c * offset[1],
                               offset[2]])  # fmt: skip
    nodes.poses[k] = wrong
    kept = []
    for e in range(len(edges)):
        if edges.i[e] == k - 1 and edges.j[e] == k:
            kept.append((e, edges.z[e]))
            edges.z[e] = relative(nodes.poses[k - 1], wrong)
        if edges.i[e] == k and edges.j[e] == k + 1:
            kept.append((e, edges.z[e]))
            edges.z[e] = relative(wrong, nodes.poses[k + 1])
    return true_k, kept


def _restore(slam, k: int, saved: tuple[np.ndarray, list]) -> None:
    slam.nodes.poses[k] = saved[0]
    for e, z in saved[1]:
        slam.edges.z[e] = z


ON = GraphSlamParams(run_final_optimization=True)


@pytest.fixture(scope="module")
def box_run():
    return _feed(ON)


def test_a_mis_registered_node_is_pulled_back_by_its_neighbours(box_run):
    slam, _, t, pose = box_run
    n = slam.nodes.n
    assert n >= 10  # a node every 0.5 m of the 5.5 m drive
    # the exact odometry and the room's walls leave the front end's nodes within millimetres
    # of the truth the test is about to compare with (precondition)
    before = slam.node_poses()
    truth = pose[np.searchsorted(t, slam.nodes.t[:n])]
    assert np.abs(before - truth).max() < 0.003
    k = n // 2
    saved = _mis_register(slam, k, np.array([0.1, 0.0, 0.02]))
    true_k = saved[0]
    try:
        edges = slam.edges.arrays()
        # both of the node's links agree with the wrong pose, so the graph is at its optimum
        # there and optimising it again moves nothing: the error has to be found in the scans
        again = optimize(slam.node_poses(), edges, 1.0, 50, 1e-12).poses
        assert np.hypot(*(again[k, :2] - true_k[:2])) == pytest.approx(0.1, abs=1e-6)
        # the node's scan matched against the 10 nodes around it (at most 2.5 m away, within
        # the front end's +-0.25 m, +-0.349 rad window) lands where it was taken, to the
        # matcher's accuracy in a box (test_matcher: 2 mm, 0.03 degrees): its new links say
        # so, the neighbours' say what they said, and the optimum has the node back
        final = slam.final_node_poses()
        assert slam.final_matched == n
        for want in (true_k, truth[k]):  # the front end's pose, and the drive's own
            assert np.hypot(*(final[k, :2] - want[:2])) < 0.005
            assert abs(wrap_angle(final[k, 2] - want[2])) < 0.003
        others = np.arange(n) != k
        d = final[others] - before[others]
        assert np.hypot(d[:, 0], d[:, 1]).max() < 0.005
        # the online graph is left as it was, wrong node and all
        assert np.hypot(*(slam.node_poses()[k, :2] - true_k[:2])) == pytest.approx(0.1, abs=1e-9)
    finally:
        _restore(slam, k, saved)  # the module's run back as the front end made it


def test_off_the_final_trajectory_is_the_online_graph():
    # off by default: on the real logs it was no general gain (GraphSlamParams)
    assert not GraphSlamParams().run_final_optimization
    slam, _, _, _ = _feed(GraphSlamParams())
    k = slam.nodes.n // 2
    _mis_register(slam, k, np.array([0.1, 0.0, 0.02]))
    assert np.array_equal(slam.final_node_poses(), slam.node_poses())
    assert slam.final_matched == 0


def test_asking_for_the_final_trajectory_on_the_way_leaves_the_online_estimate_bit_for_bit(
    box_run,
):
    _, est, _, _ = box_run
    _, est_asked, _, _ = _feed(ON, final_every=7)
    assert np.array_equal(est, est_asked)


def test_two_sided_nodes_and_relinked_edges():
    poses = np.column_stack([np.arange(8.0), np.zeros(8), np.zeros(8)])
    poses[6, 1] = 20.0  # far from node 5: not in its map
    assert two_sided_nodes(poses, 5, 2, 10.0).tolist() == [3, 4, 7]
    assert two_sided_nodes(poses, 0, 2, 10.0).tolist() == [1, 2]
    # links 0-1, 1-2, 2-3 and a loop edge 0-3; node 2's match failed: only 0-1 is replaced
    z = np.array([[1.0, 0, 0], [1.0, 0, 0], [1.0, 0, 0], [3.0, 0, 0]])
    sigma = np.full((4, 3), 0.3)
    edges = Edges(np.array([0, 1, 2, 0]), np.array([1, 2, 3, 3]), z, sigma,
                  np.array([False, False, False, True]), np.zeros(4))  # fmt: skip
    match = np.array([[0.0, 0, 0], [1.1, 0.1, 0.05], [0, 0, 0], [3.0, 0, 0]])
    out = relink_edges(edges, np.array([True, True, False, True]), match, (0.05, 0.05, 0.02))
    # node 0's match is at the origin, unturned: node 1's match is the relative pose itself
    assert np.allclose(out.z[0], [1.1, 0.1, 0.05])
    assert np.allclose(out.sigma[0], [0.05, 0.05, 0.02])
    assert np.array_equal(out.z[1:], z[1:]) and np.array_equal(out.sigma[1:], sigma[1:])


def test_the_final_map_is_drawn_where_the_final_step_put_the_nodes(box_run):
    """mapqual slam writes final_trajectory beside final_occupancy: with the step on, the map
    of a mis-registered node's scan moves with the node; with it off, it is the online map."""
    slam, _, _, _ = box_run
    k = slam.nodes.n // 2
    online_ok = slam.final_occupancy()  # every node in place: both maps of the same poses
    saved = _mis_register(slam, k, np.array([0.1, 0.0, 0.02]))
    try:
        slam._grid = None  # the online map, redrawn with the node where it now is (0.1 m off)
        online = slam.occupancy()
        final = slam.final_occupancy()
    finally:
        _restore(slam, k, saved)
        slam._grid = None
    assert online_ok.shape == final.shape and np.array_equal(online_ok.origin, final.origin)
    # the final map is the map of the poses in place (the node was pulled back to within
    # 5 mm, a tenth of a cell), the online one has the node's walls 0.1 m and 0.02 rad off:
    # whole wall segments a cell or two away (the room's walls are 612 occupied cells)
    assert np.array_equal(final.occupied, online_ok.occupied)
    assert np.sum(online.occupied != online_ok.occupied) > 100
    off, _, _, _ = _feed(GraphSlamParams())
    assert off.final_occupancy() is off.occupancy()
