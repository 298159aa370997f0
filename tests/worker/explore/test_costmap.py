"""Costmap: costmap_2d's inflation formula, incremental updates, footprint collision test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.explore import costmap_kernels as ck
from worker.explore import dwa_kernels as dk
from worker.explore import local_kernels as lk
from worker.explore.costmap import GlobalCostmap, LocalCostmap, cost_from_distance
from worker.explore.flat_params import explore_params
from worker.explore.params import ExploreParams

RES = 0.05


@pytest.mark.parametrize(
    ("d", "expected"),
    [
        (0.0, 254),  # the obstacle cell itself
        (0.05, 253),  # inside the 0.2 m inscribed radius
        (0.2, 253),  # on it
        (0.5, 26),  # 252 * exp(-7.5 * 0.3) = 26.56 -> 26
        (0.3, 119),  # 252 * exp(-7.5 * 0.1) = 119.03 -> 119
        (1.0, 0),  # 252 * exp(-6) = 0.62 -> 0
        (2.3, 0),  # beyond the inflation radius
    ],
)
def test_inflation_cost_matches_costmap_2d_formula(d, expected):
    assert ck.inflation_cost(d, 0.2, 7.5, 2.25) == expected


def test_effective_radius_is_where_cost_truncates_to_zero():
    r = ck.effective_inflation_cells(RES, 0.2, 7.5, 2.25)
    # 252 exp(-7.5 (d - 0.2)) < 1  <=>  d > 0.2 + ln(252) / 7.5 = 0.937 m -> 19 cells (+1 spare)
    assert r == 20
    assert ck.inflation_cost((r - 1) * RES, 0.2, 7.5, 2.25) == 0


def _prob_with_wall(h=60, w=80):
    prob = np.full((h, w), 0.05, dtype=np.float32)  # all known free
    prob[:, 40] = 0.9  # a wall column at ix = 40
    return prob


def test_global_costmap_costs_by_distance_to_wall():
    cm = GlobalCostmap(ExploreParams().costmap)
    cm.update(_prob_with_wall(), RES, (0.0, 0.0))
    row = cm.inflated[30]
    assert row[40] == 254
    for dx in range(1, 25):
        expected = ck.inflation_cost(dx * RES, 0.2, 7.5, 2.25)
        assert row[40 + dx] == expected
        assert row[40 - dx] == expected
    assert row[41] == 253 and row[44] == 253 and row[45] < 253


def test_unknown_cells_are_no_information_unless_inscribed():
    prob = _prob_with_wall()
    prob[:, 42:] = np.nan
    cm = GlobalCostmap(ExploreParams().costmap)
    cm.update(prob, RES, (0.0, 0.0))
    master = cm.master()
    assert master[10, 41] == 253  # known, inscribed
    assert master[10, 43] == 253  # unknown but within the inscribed radius: costmap_2d keeps 253
    assert master[10, 50] == 255  # unknown, farther: NO_INFORMATION
    assert master[10, 30] == cm.inflated[10, 30] < 253


def test_incremental_update_equals_full_rebuild():
    rng = np.random.default_rng(3)
    prob = np.full((90, 110), np.nan, dtype=np.float32)
    inc = GlobalCostmap(ExploreParams().costmap)
    inc.update(prob, RES, (1.0, -2.0))
    for _ in range(12):
        y0, x0 = rng.integers(0, 80), rng.integers(0, 100)
        patch = rng.choice([np.nan, 0.05, 0.9], size=(10, 10), p=[0.3, 0.5, 0.2])
        prob[y0 : y0 + 10, x0 : x0 + 10] = patch
        window_m = (
            1.0 + x0 * RES,
            -2.0 + y0 * RES,
            1.0 + (x0 + 9.5) * RES,
            -2.0 + (y0 + 9.5) * RES,
        )
        changed = inc.update(prob, RES, (1.0, -2.0), window_m=window_m)
        if changed[1] > changed[0]:  # the changes lie inside the window that was re-read
            assert y0 <= changed[0] and changed[1] <= y0 + 10
    full = GlobalCostmap(ExploreParams().costmap)
    full.update(prob, RES, (1.0, -2.0))
    np.testing.assert_array_equal(inc.lethal, full.lethal)
    np.testing.assert_array_equal(inc.unknown, full.unknown)
    np.testing.assert_array_equal(inc.inflated, full.inflated)


def test_inflation_agrees_with_an_exact_distance_transform():
    from scipy import ndimage

    rng = np.random.default_rng(8)
    prob = np.where(rng.random((70, 70)) < 0.02, 0.9, 0.05).astype(np.float32)
    cm = GlobalCostmap(ExploreParams().costmap)
    cm.update(prob, RES, (0.0, 0.0))
    dist = ndimage.distance_transform_edt(prob < 0.25) * RES
    expected = cost_from_distance(dist, 0.2, 7.5, 2.25)
    # float32/float64 rounding can move a value across an integer by one
    assert np.max(np.abs(expected.astype(int) - cm.inflated.astype(int))) <= 1
    assert np.mean(expected == cm.inflated) > 0.99


def test_growing_cropped_map_keeps_one_frame_and_matches_a_fresh_costmap():
    p = explore_params(growth_margin=1.0)
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(_prob_with_wall(), RES, (0.0, 0.0))
    frame = cm.frame_id
    bigger = np.full((80, 100), np.nan, dtype=np.float32)
    bigger[10:70, 10:90] = _prob_with_wall()
    bigger[:, 95] = 0.9  # a new wall beyond the old frame
    cm.update(bigger, RES, (-0.5, -0.5))
    assert cm.frame_id != frame
    # grown by the incoming map plus a 1 m (20 cell) margin on the sides it outgrew
    assert cm.shape == (60 + 10 + 20 + 10 + 20, 80 + 10 + 20 + 10 + 20)
    fresh = GlobalCostmap(p.costmap, p.doors.door_align)
    fresh.update(bigger, RES, (-0.5, -0.5))
    oy, ox = (np.round((fresh.origin - cm.origin) / RES).astype(int))[::-1]
    sub = (slice(oy, oy + 80), slice(ox, ox + 100))
    np.testing.assert_array_equal(cm.lethal[sub], fresh.lethal)
    np.testing.assert_array_equal(cm.unknown[sub], fresh.unknown)
    np.testing.assert_array_equal(cm.inflated[sub], fresh.inflated)
    assert cm.unknown.sum() - cm.unknown[sub].sum() == cm.unknown.size - 80 * 100
    # the same map again, cropped smaller: fits, so the frame stays
    frame = cm.frame_id
    cm.update(bigger[10:70, 10:90], RES, (0.0, 0.0))
    assert cm.frame_id == frame


def _single_obstacle_layers(cx, cy, n=40):
    """Local layers of a window (origin 0, 0) with one obstacle cell (cx, cy)."""
    pts = np.array([[(cx + 0.5) * RES, (cy + 0.5) * RES]])
    lethal, near, inner, _ = lk.local_layers(
        pts[:, 0], pts[:, 1], 0.0, 0.0, RES, n,
        lk.disc_half_widths(5 * math.sqrt(2) + 0.01), lk.disc_half_widths(4.0),
        np.zeros((1, 1), bool), np.zeros((1, 1), np.uint8), -(10**6), -(10**6), n,
        0.0, 0.0, 0.0, -1.0,
    )  # fmt: skip
    return lethal, near, inner


def test_footprint_square_not_circle():
    # Robot at the centre of cell (20, 20) = (1.025, 1.025); obstacle cell (26, 20) spans
    # x in [1.3, 1.35], y in [1.0, 1.05].
    lethal, near, inner = _single_obstacle_layers(26, 20)
    x, y = 1.025, 1.025
    # facing +x: the front edge is at x = 1.225 < 1.3 -> free
    assert not ck.footprint_collides(lethal, near, inner, 0.0, 0.0, RES, x, y, 0.0, 0.2)
    # moved 0.1 m forwards: the front edge reaches 1.325 -> inside the obstacle cell
    assert ck.footprint_collides(lethal, near, inner, 0.0, 0.0, RES, x + 0.1, y, 0.0, 0.2)
    # rotated by 45 degrees the corner reaches 1.025 + 0.283 = 1.308 -> collides
    assert ck.footprint_collides(lethal, near, inner, 0.0, 0.0, RES, x, y, math.pi / 4, 0.2)


def test_local_layers_distances():
    lethal, near, inner = _single_obstacle_layers(20, 20)
    assert lethal.sum() == 1 and lethal[20, 20]
    assert inner[20, 24] and not inner[20, 25] and inner[23, 22] and not inner[23, 23]
    # near: within 5 sqrt(2) = 7.07 cells
    assert near[20, 27] and not near[20, 28] and near[25, 25] and not near[25, 26]


def test_local_costmap_marks_hits_only_and_clears():
    p = ExploreParams()
    local = LocalCostmap(p.costmap, p.dwa, RES)
    angles = np.array([0.0, math.pi / 2])
    local.add_scan(0.0, np.array([5.0, 5.0, 0.0]), np.array([1.0, 30.0]), angles, 30.0)
    local.build(5.0, 5.0)
    hx, hy = np.argwhere(local.lethal)[0][::-1]
    assert local.lethal.sum() == 1  # the max-range beam marks nothing
    assert abs(local.origin[0] + (hx + 0.5) * RES - 6.0) <= RES
    assert abs(local.origin[1] + (hy + 0.5) * RES - 5.0) <= RES
    assert local.cost[hy, hx] == 254 and local.cost[hy, hx - 4] == 253
    assert local.cost[hy, hx - 5] == 0  # no map: inflation comes from the global costmap
    # a second scan 2 s later: the first one has expired (persistence 1 s)
    local.add_scan(2.0, np.array([5.0, 5.0, 0.0]), np.array([2.0, 30.0]), angles, 30.0)
    local.build(5.0, 5.0)
    assert local.lethal.sum() == 1
    local.add_scan(2.5, np.array([5.0, 5.0, 0.0]), np.array([1.5, 30.0]), angles, 30.0)
    local.clear()  # recovery: only the newest scan stays
    local.build(5.0, 5.0)
    assert local.lethal.sum() == 1


def test_local_costmap_raytrace_clears_earlier_marks_its_beams_cross():
    # a noisy short reading marks a ghost at x = 6.0 m; the next scan's beam along the same
    # bearing reaches the wall at 7.0 m through the ghost's cell: with raytrace clearing the
    # ghost goes, without it the ghost stays for local_persistence (1 s)
    angles = np.array([0.0, math.pi / 2])
    pose = np.array([5.02, 5.02, 0.0])
    for raytrace, ghosts in ((True, 0), (False, 1)):
        local = LocalCostmap(
            explore_params(local_raytrace=raytrace).costmap,
            explore_params(local_raytrace=raytrace).dwa,
            RES,
        )
        local.add_scan(0.0, pose, np.array([1.0, 30.0]), angles, 30.0)
        local.add_scan(0.1, pose, np.array([2.0, 30.0]), angles, 30.0)
        local.build(5.0, 5.0)
        wall = [(7.025, 5.025)]
        assert _marked(local) == (wall if ghosts == 0 else [(6.025, 5.025), *wall])
    local = LocalCostmap(
        explore_params(local_raytrace=True).costmap, explore_params(local_raytrace=True).dwa, RES
    )
    # a beam ending in the ghost's own cell, one without a return, and one on another
    # bearing leave it; only a beam through the cell clears
    local.add_points(0.0, np.array([[6.02, 5.02]]))
    local.add_scan(0.1, pose, np.array([1.0, 30.0]), angles, 30.0)  # ends in the same cell
    local.add_scan(0.2, pose, np.array([30.0, 30.0]), angles, 30.0)  # no return on the bearing
    local.add_scan(0.3, pose, np.array([30.0, 0.5]), angles, 30.0)  # the other bearing only
    local.build(5.0, 5.0)
    assert _marked(local) == [(5.025, 5.525), (6.025, 5.025)]
    local.add_scan(0.4, pose, np.array([1.5, 30.0]), angles, 30.0)  # through the ghost's cell
    local.build(5.0, 5.0)
    assert _marked(local) == [(5.025, 5.525), (6.525, 5.025)]


def _marked(local):
    """Centres [m] of the local costmap's lethal cells, sorted."""
    cy, cx = np.nonzero(local.lethal)
    xs = local.origin[0] + (cx + 0.5) * local.resolution
    ys = local.origin[1] + (cy + 0.5) * local.resolution
    return sorted((round(float(x), 3), round(float(y), 3)) for x, y in zip(xs, ys, strict=True))


def test_local_costmap_includes_map_obstacles_and_inflation():
    p = ExploreParams()
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(_prob_with_wall(), RES, (0.0, 0.0))  # wall at x in [2.0, 2.05]
    local = LocalCostmap(p.costmap, p.dwa, RES)
    local.build(1.5, 1.5, cm)
    wx = int(round((2.0 - local.origin[0]) / RES))
    wy = int(round((1.5 - local.origin[1]) / RES))
    assert local.lethal[wy, wx] and local.cost[wy, wx] == 254
    assert local.cost[wy, wx - 6] == cm.inflated[30, 34] < 253


def test_local_costmap_clears_the_robots_own_footprint():
    p = ExploreParams()
    local = LocalCostmap(p.costmap, p.dwa, RES)
    local.add_points(0.0, np.array([[5.1, 5.0], [5.5, 5.0]]))  # one under the robot
    local.build(5.0, 5.0, None, 0.0)
    assert local.lethal.sum() == 1
    local.build(5.0, 5.0)  # no heading given: nothing cleared
    assert local.lethal.sum() == 2


def test_a_map_wall_the_footprint_overlaps_does_not_wedge_the_robot():
    # The office_a deadlock: the SLAM map draws a wall a cell nearer than it is, so that the
    # robot's footprint (0.2 m half side) at 0.22 m from the wall's cell edge, turned 0.57 rad,
    # overlaps it; with that cell kept every motion collided, backing away included.
    p = ExploreParams()
    cm = GlobalCostmap(p.costmap, p.doors.door_align)
    cm.update(_prob_with_wall(), RES, (0.0, 0.0))  # wall cells x in [2.0, 2.05)
    x, y, th = 1.77, 1.5, 0.57  # corner at x = 1.77 + 0.2 (cos + sin) = 2.05: in the wall
    local = LocalCostmap(p.costmap, p.dwa, RES)
    local.build(x, y, cm, th)
    args = (local.lethal, local.near, local.inner, *local.origin, RES)
    half = p.costmap.footprint_half_m
    assert not ck.footprint_collides(*args, x, y, th, half)
    back = dk.motion_legal(x, y, th, -0.1, 0.0, 1.0, *args, half, p.dwa.sim_granularity)
    on = dk.motion_legal(x, y, th, 0.1, 0.0, 1.0, *args, half, p.dwa.sim_granularity)
    assert back and not on  # away from the wall is free; into it still collides
    local.build(x, y, cm)  # without the heading nothing is cleared: the wall is there
    assert ck.footprint_collides(local.lethal, local.near, local.inner, *local.origin, RES,
                                 x, y, th, half)  # fmt: skip
    assert local.lethal[int((1.5 - local.origin[1]) / RES), int((2.02 - local.origin[0]) / RES)]


def test_local_layers_equal_a_disc_dilation():
    # independent check: scipy's binary dilation with the disc of disc_offsets
    from scipy import ndimage

    rng = np.random.default_rng(4)
    n, radius = 60, 6.3
    pts = rng.uniform(0.0, n * RES, size=(40, 2))
    lethal, near, inner, _ = lk.local_layers(
        pts[:, 0].copy(), pts[:, 1].copy(), 0.0, 0.0, RES, n,
        lk.disc_half_widths(radius), lk.disc_half_widths(2.5),
        np.zeros((1, 1), np.bool_), np.zeros((1, 1), np.uint8), -(10**6), -(10**6), 0,
        0.0, 0.0, 0.0, -1.0,
    )  # fmt: skip
    for layer, r in ((near, radius), (inner, 2.5)):
        off = lk.disc_offsets(r)
        R = int(np.abs(off).max())
        disc = np.zeros((2 * R + 1, 2 * R + 1), dtype=bool)
        disc[off[:, 0] + R, off[:, 1] + R] = True
        np.testing.assert_array_equal(layer, ndimage.binary_dilation(lethal, structure=disc))


def test_a_robot_touching_an_obstacle_backs_away_from_it():
    # The footprint's front edge 1 cm into the cell of a wall the scans and the map both hold
    # (the cells are 5 cm): every motion "collides" at the start pose; the way out backs off.
    from worker.explore.navigator import Navigator
    from worker.explore.recovery import unwedge

    p = ExploreParams()
    angles = np.linspace(-2.35, 2.35, 541)
    nav = Navigator(p, angles, 30.0)
    nav.update_map(_prob_with_wall(), RES, (0.0, 0.0), True)  # wall cells x in [2.0, 2.05)
    face = np.column_stack((np.full(21, 2.0), np.linspace(1.0, 2.0, 21)))
    nav.local.add_points(0.0, face)
    pose = np.array([1.81, 1.5, 0.0])  # front edge at x = 2.01
    v, w = unwedge(p.recovery, p.dwa, nav.local, nav.costmap, pose)
    assert v < 0
    # independent check: one second of it leaves the 0.4 m square clear of the face by more
    x, y, th = 1.81, 1.5, 0.0
    for _ in range(100):
        x, y, th = x + v * math.cos(th) * 0.01, y + v * math.sin(th) * 0.01, th + w * 0.01
    c, s = math.cos(th), math.sin(th)
    u = np.abs((face[:, 0] - x) * c + (face[:, 1] - y) * s) - 0.2
    q = np.abs(-(face[:, 0] - x) * s + (face[:, 1] - y) * c) - 0.2
    assert np.min(np.hypot(np.maximum(u, 0), np.maximum(q, 0))) > 0.05
    assert (
        unwedge(p.recovery, p.dwa, nav.local, nav.costmap, np.array([1.5, 1.5, 0.0])) is None
    )  # clear of it: nothing to do


def test_a_robot_touching_an_obstacle_at_its_side_slides_back_along_it():
    # office_b_furnitures: a table edge under the footprint's right side, a chair 6 cm ahead;
    # no turn is legal and backing off leaves the side gap as it is, but gets the robot out
    from worker.explore.navigator import Navigator
    from worker.explore.recovery import unwedge

    p = ExploreParams()
    nav = Navigator(p, np.linspace(-2.35, 2.35, 541), 30.0)
    free = np.full((60, 80), 0.05, dtype=np.float32)
    nav.update_map(free, RES, (0.0, 0.0), True)
    side = np.column_stack((np.linspace(1.5, 1.75, 11), np.full(11, 1.305)))
    ahead = np.column_stack((np.full(11, 1.86), np.linspace(1.35, 1.65, 11)))
    pts = np.concatenate([side, ahead])
    nav.local.add_points(0.0, pts)
    v, w = unwedge(p.recovery, p.dwa, nav.local, nav.costmap, np.array([1.6, 1.5, 0.0]))
    assert v < 0
    # independent check: a second of it takes the 0.4 m square no nearer any obstacle point
    x, y, th = 1.6, 1.5, 0.0

    def gap(x, y, th):
        c, s = math.cos(th), math.sin(th)
        u = np.abs((pts[:, 0] - x) * c + (pts[:, 1] - y) * s) - 0.2
        q = np.abs(-(pts[:, 0] - x) * s + (pts[:, 1] - y) * c) - 0.2
        return np.hypot(np.maximum(u, 0), np.maximum(q, 0))

    before = gap(x, y, th)
    for _ in range(100):
        x, y, th = x + v * math.cos(th) * 0.01, y + v * math.sin(th) * 0.01, th + w * 0.01
    assert np.all(gap(x, y, th) >= before - 1e-3)
