"""DWA local planner: follows the path, avoids obstacles, turns in place, respects limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.explore import dwa_kernels as dk
from worker.explore.costmap import GlobalCostmap, LocalCostmap
from worker.explore.dwa import DwaPlanner
from worker.explore.params import ExploreParams
from worker.explore.planner import GlobalPlanner

RES = 0.05


def _wall(x0, x1, y0, y1, step=0.02):
    xs = np.arange(x0, x1 + 1e-9, step)
    ys = np.arange(y0, y1 + 1e-9, step)
    return np.array([(x, y) for x in xs for y in ys])


def _local(points, pose, p, costmap=None):
    local = LocalCostmap(p.costmap, p.dwa, RES)
    if len(points):
        local.add_points(0.0, points)
    local.build(pose[0], pose[1], costmap)
    return local


def _straight_path(x0, x1, y):
    xs = np.arange(x0, x1, RES)
    return np.column_stack((xs, np.full_like(xs, y)))


def test_wavefront_is_manhattan_distance_around_obstacles():
    cost = np.zeros((5, 7), dtype=np.uint8)
    cost[0:4, 3] = 253  # a wall with a gap at the top row (iy = 4)
    d = dk.wavefront(np.array([[0, 0]]), cost, 0.1)
    assert math.isclose(d[0, 2], 0.2, rel_tol=1e-6)
    assert d[0, 3] == np.inf
    # to (0, 4): up 4, across 4, down 4 -> 12 steps
    assert math.isclose(d[0, 4], 1.2, rel_tol=1e-6)


@pytest.mark.parametrize("seed", range(6))
def test_a_wavefront_asked_for_a_square_gives_its_cells_what_the_whole_search_does(seed):
    """The search stops once the square's reachable cells are all reached; the square must
    then hold the whole search's distances, cell for cell, on random obstacle fields (some
    with cells of the square walled off, which keep the search going to its end)."""
    rng = np.random.default_rng(seed)
    n = 60
    cost = np.where(rng.random((n, n)) < 0.3, 254, 0).astype(np.uint8)
    seeds = rng.integers(0, n, size=(int(rng.integers(1, 6)), 2))
    full = dk.wavefront(seeds, cost, 0.05)
    for cy, cx, r in ((30, 30, 5), (2, 57, 8), (int(seeds[0, 0]), int(seeds[0, 1]), 0)):
        part = np.empty((n, n), dtype=np.float32)
        dk.wavefront_into(seeds, cost, 0.05, part, np.empty(n * n, np.int64), cy, cx, r)
        sq = (slice(max(0, cy - r), cy + r + 1), slice(max(0, cx - r), cx + r + 1))
        assert np.array_equal(part[sq], full[sq])
        # what lies outside was not all searched (the point of the square): never wrong
        # where it was, inf where it was not
        out = part != full
        assert np.all(part[out] == np.inf)


def test_free_straight_path_accelerates_forwards_within_the_window():
    p = ExploreParams()
    pose = np.array([3.0, 3.0, 0.0])
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(_straight_path(3.0, 8.0, 3.0))
    cmd = dwa.command(pose, 0.0, 0.0, _local([], pose, p), None)
    assert cmd.legal and cmd.kind == "forward"
    assert math.isclose(cmd.v, 0.15)  # 0 + acc_lim_x (1.5) * 0.1 s: fastest in the window
    assert abs(cmd.w) < 1e-9
    cmd = dwa.command(pose, 0.85, 0.0, _local([], pose, p), None)
    assert math.isclose(cmd.v, 0.85) and abs(cmd.w) < 1e-9


def test_path_behind_makes_it_turn_in_place():
    p = ExploreParams()
    pose = np.array([3.0, 3.0, 0.0])
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(np.column_stack((np.linspace(3.0, 0.5, 51), np.full(51, 3.0))))
    cmd = dwa.command(pose, 0.0, 0.0, _local([], pose, p), None)
    assert cmd.legal and cmd.kind == "rotate" and abs(cmd.w) >= p.dwa.min_in_place_vel_theta


def test_wall_ahead_with_path_through_it_has_no_forward_command():
    p = ExploreParams()
    pose = np.array([3.0, 3.0, 0.0])
    wall = _wall(3.3, 3.32, 0.5, 5.5)  # across the whole window, 0.1 m in front of the robot
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(_straight_path(3.0, 8.0, 3.0))
    cmd = dwa.command(pose, 0.0, 0.0, _local(wall, pose, p), None)
    assert cmd.kind != "forward"


def test_drives_around_a_post_along_the_global_plan_without_touching_it():
    p = ExploreParams()
    pose = np.array([1.0, 3.025, 0.0])
    post = _wall(2.0, 2.1, 2.95, 3.1)  # a 0.1 m post 1 m ahead, on the straight line
    prob = np.full((120, 160), 0.05, dtype=np.float32)
    cells = np.floor(post / RES).astype(int)
    prob[cells[:, 1], cells[:, 0]] = 0.9
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(prob, RES, (0.0, 0.0))
    path = GlobalPlanner(p.planner).plan(cm, pose[:2], (4.0, 3.025))
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(path)
    x, v, w = pose.copy(), 0.0, 0.0
    closest = np.inf
    for _ in range(200):  # 20 s, integrating the unicycle with the commanded velocities
        local = _local(post, x, p, cm)
        cmd = dwa.command(x, v, w, local, None)  # no legal command: (0, 0), the robot stops
        v, w = cmd.v, cmd.w
        x[0] += v * math.cos(x[2]) * 0.1
        x[1] += v * math.sin(x[2]) * 0.1
        x[2] += w * 0.1
        # independent check: no point of the post inside the robot's 0.4 m square
        c, s_ = math.cos(x[2]), math.sin(x[2])
        u = (post[:, 0] - x[0]) * c + (post[:, 1] - x[1]) * s_
        v_ = -(post[:, 0] - x[0]) * s_ + (post[:, 1] - x[1]) * c
        assert not np.any((np.abs(u) < 0.2) & (np.abs(v_) < 0.2))
        closest = min(closest, float(np.min(np.hypot(*(post - x[:2]).T))))
        if dwa.goal_reached(x, None):
            break
    assert dwa.goal_reached(x, None)
    assert closest > 0.2  # the centre never came nearer than the footprint's half side


def test_goal_alignment_then_reached():
    p = ExploreParams()
    pose = np.array([3.0, 3.0, 0.0])
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(np.array([[3.0, 3.0], [3.1, 3.0]]))
    local = _local([], pose, p)
    cmd = dwa.command(pose, 0.0, 0.0, local, math.pi / 2)
    assert cmd.kind == "align" and cmd.w > 0 and cmd.v == 0.0
    assert not dwa.goal_reached(pose, math.pi / 2)
    pose[2] = math.pi / 2 - 0.1
    assert dwa.goal_reached(pose, math.pi / 2)
    assert dwa.command(pose, 0.0, 0.0, local, math.pi / 2).kind == "aligned"


def _ring(radius, gap_centre, gap_half, step=0.01):
    """Obstacle points on a circle around (3, 3) but for a gap (angles in rad)."""
    a = np.arange(-math.pi, math.pi, step / radius)
    keep = np.abs((a - gap_centre + math.pi) % (2 * math.pi) - math.pi) > gap_half
    return np.column_stack((3.0 + radius * np.cos(a[keep]), 3.0 + radius * np.sin(a[keep])))


def test_turns_in_place_when_no_turn_looks_at_a_reachable_cell():
    # inside a ring of 0.5 m radius whose only gap is behind: every in-place turn ends looking
    # at a cell within the inscribed radius of the ring (no goal distance there), yet turning
    # towards the gap is what the robot must do
    p = ExploreParams()
    pose = np.array([3.0, 3.0, 0.0])
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(np.column_stack((np.linspace(3.0, 0.5, 51), np.full(51, 3.0))))
    cmd = dwa.command(pose, 0.0, 0.0, _local(_ring(0.5, math.pi, 1.0), pose, p), None)
    assert cmd.legal and cmd.kind == "rotate"


def test_keeps_turning_the_same_way_until_it_faces_a_path_behind():
    p = ExploreParams()
    x = np.array([3.0, 3.0, 0.3])
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(np.column_stack((np.linspace(3.0, 0.5, 51), np.full(51, 3.0))))
    v = w = 0.0
    for _ in range(60):  # 6 s at 10 Hz: half a turn at 0.7 rad/s takes 4.5 s
        cmd = dwa.command(x, v, w, _local([], x, p), None)
        v, w = cmd.v, cmd.w
        x[0] += v * math.cos(x[2]) * 0.1
        x[1] += v * math.sin(x[2]) * 0.1
        x[2] += w * 0.1
    assert abs((x[2] + math.pi) % (2 * math.pi) - math.pi) > 2.5  # facing -x
    assert x[0] < 2.9  # and on its way along the path


def test_oscillation_flags_block_a_way_only_after_a_reversal():
    dwa = DwaPlanner(ExploreParams().dwa, ExploreParams().costmap)
    pose = np.array([3.0, 3.0, 0.0])
    for _ in range(3):  # turning left (positive) again and again is no oscillation
        dwa._track_oscillation(pose, 1, 0.5)
    assert not dwa._stuck_left and not dwa._stuck_right
    dwa._track_oscillation(pose, 1, -0.5)  # left, then right: left is blocked
    assert dwa._stuck_left and not dwa._stuck_right
    dwa._track_oscillation(pose + np.array([0.3, 0.0, 0.0]), 0, 0.0)  # moved 0.3 m: cleared
    assert not dwa._stuck_left and not dwa._stuck_right


def test_score_bound_skips_only_trajectories_that_cannot_win():
    p = ExploreParams()
    pose = np.array([3.0, 3.0, 0.0])
    local = _local(_wall(3.0, 3.05, 3.25, 3.3), pose, p)  # a post 0.25 m to the left
    path = _straight_path(3.0, 8.0, 3.0)
    dwa = DwaPlanner(p.dwa, p.costmap)
    dwa.set_plan(path)
    seeds, goal = dwa._local_plan(pose, local)
    pd = dk.wavefront(seeds, local.cost, local.resolution)
    gd = dk.wavefront(goal, local.cost, local.resolution)
    args = (local.lethal, local.near, local.inner, local.cost, pd, gd,
            float(local.origin[0]), float(local.origin[1]), RES, dwa.prm)  # fmt: skip
    free = dk.score_trajectory(3.0, 3.0, 0.0, 0.3, 0.0, *args)
    hits = dk.score_trajectory(3.0, 3.0, 0.0, 0.0, 0.7, *args)  # a corner sweeps the post
    assert free > 0 and hits == -1.0
    assert dk.score_trajectory(3.0, 3.0, 0.0, 0.3, 0.0, *args, -1.0, free + 1e-6) == free
    assert dk.score_trajectory(3.0, 3.0, 0.0, 0.3, 0.0, *args, -1.0, free) == -3.0
