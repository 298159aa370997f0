"""Ray casting against closed-form distances in rectangular rooms, and grid-traversal edge cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.sim.laser import LaserSpec
from worker.world import World
from worker.world.raycast import (
    cast_ray,
    cast_scan,
    cast_scan_skip,
    cast_scans,
    cast_scans_skip,
    jump_map,
)

RES = 0.05


def room(width_cells: int, height_cells: int, wall: int = 1) -> np.ndarray:
    """A rectangular room: `wall` cells thick on every side, free inside."""
    occ = np.ones((height_cells, width_cells), dtype=bool)
    occ[wall:-wall, wall:-wall] = False
    return occ


def analytic_range(px, py, direction, x0, x1, y0, y1, range_max):
    """Distance from (px, py) inside the box [x0, x1] x [y0, y1] to its boundary along direction."""
    c, s = math.cos(direction), math.sin(direction)
    hits = []
    if c > 1e-12:
        hits.append((x1 - px) / c)
    if c < -1e-12:
        hits.append((x0 - px) / c)
    if s > 1e-12:
        hits.append((y1 - py) / s)
    if s < -1e-12:
        hits.append((y0 - py) / s)
    return min(min(hits), range_max)


def test_every_beam_matches_the_analytic_distance_in_a_rectangular_room(rng):
    occ = room(160, 90)  # free interior x in [0.05, 7.95], y in [0.05, 4.45] with origin 0
    ox, oy = -2.0, 1.0
    x0, x1, y0, y1 = ox + RES, ox + 159 * RES, oy + RES, oy + 89 * RES
    laser = LaserSpec()
    for _ in range(40):
        px = rng.uniform(x0 + 0.01, x1 - 0.01)
        py = rng.uniform(y0 + 0.01, y1 - 0.01)
        theta = rng.uniform(-math.pi, math.pi)
        ranges = cast_scan(occ, RES, ox, oy, px, py, theta, laser.angles, laser.range_max)
        expected = [
            analytic_range(px, py, theta + a, x0, x1, y0, y1, laser.range_max) for a in laser.angles
        ]
        # The walls lie on cell boundaries, so the exact traversal is exact up to rounding.
        np.testing.assert_allclose(ranges, expected, atol=1e-9)
        assert np.all(np.abs(ranges - expected) <= RES)


def test_readings_beyond_range_are_range_max():
    occ = room(400, 400)  # 20 m x 20 m
    ranges = cast_scan(occ, RES, 0.0, 0.0, 10.0, 10.0, 0.0, np.array([0.0, math.pi / 2]), 5.0)
    np.testing.assert_array_equal(ranges, [5.0, 5.0])
    ranges = cast_scan(occ, RES, 0.0, 0.0, 10.0, 10.0, 0.0, np.array([0.0]), 30.0)
    assert ranges[0] == pytest.approx(9.95, abs=1e-9)


def test_the_grid_border_counts_as_a_wall():
    occ = np.zeros((20, 40), dtype=bool)  # no walls at all: 2 m x 1 m of free space
    r = cast_scan(occ, RES, 0.0, 0.0, 0.5, 0.5, 0.0, np.array([0.0, math.pi, math.pi / 2]), 30.0)
    np.testing.assert_allclose(r, [1.5, 0.5, 0.5], atol=1e-9)


def test_a_beam_starting_inside_an_obstacle_reads_zero():
    occ = room(20, 20)
    assert cast_ray(occ, RES, 0.0, 0.0, 0.02, 0.5, 0.3, 30.0) == 0.0
    assert cast_ray(occ, RES, 0.0, 0.0, -1.0, 0.5, 0.3, 30.0) == 0.0  # outside the grid


def test_a_beam_never_slips_through_a_diagonal_wall_gap():
    # A diagonal wall of cells touching only at corners; a 45-degree beam aimed exactly at the
    # shared corners must stop at the wall, not pass between the cells.
    n = 60
    occ = np.zeros((n, n), dtype=bool)
    for i in range(n):
        occ[i, n - 1 - i] = True  # anti-diagonal staircase
    # From the centre of cell (10, 10), going up-right at 45 degrees along the cell diagonals
    # the beam passes exactly through cell corners.
    x = y = 10.5 * RES
    r = cast_ray(occ, RES, 0.0, 0.0, x, y, math.pi / 4, 30.0)
    # The wall cell on the diagonal is (ix, iy) with ix + iy = n - 1; the beam reaches the
    # corner region of cells (29, 29)/(30, 29)/(29, 30) after crossing to x = 29.5*RES.
    assert r < 30.0
    hit_x, hit_y = x + r * math.cos(math.pi / 4), y + r * math.sin(math.pi / 4)
    assert hit_x + hit_y <= (n + 1) * RES  # stopped at the staircase, not beyond it
    # Same for every 45-degree beam crossing the staircase from a corner-aligned start.
    for k in range(5, 25):
        r = cast_ray(occ, RES, 0.0, 0.0, k * RES, (k + 1) * RES, math.pi / 4, 30.0)
        assert r < 30.0


def test_skipping_gives_the_same_ranges_as_plain_traversal(rng):
    occ = room(300, 200)
    # Clutter: random pillars and a thin diagonal wall.
    for _ in range(60):
        ix, iy = rng.integers(5, 290), rng.integers(5, 190)
        occ[iy : iy + rng.integers(1, 6), ix : ix + rng.integers(1, 6)] = True
    for i in range(120):
        occ[40 + i // 2, 60 + i] = True
    world = World.from_array(occ, RES)
    jump = jump_map(occ, world.clearance, RES)
    assert jump.dtype == np.uint8 and (jump[occ] == 0).all() and (jump[~occ] >= 1).all()
    free = np.argwhere(~occ)
    pick = free[rng.choice(len(free), 60)]
    poses = np.column_stack(
        [
            (pick[:, 1] + rng.uniform(0, 1, 60)) * RES,
            (pick[:, 0] + rng.uniform(0, 1, 60)) * RES,
            rng.uniform(-math.pi, math.pi, 60),
        ]
    )
    angles = LaserSpec().angles
    plain = cast_scans(occ, RES, 0.0, 0.0, poses, angles, 30.0)
    fast = cast_scans_skip(jump, RES, 0.0, 0.0, poses, angles, 30.0)
    np.testing.assert_allclose(fast, plain, atol=1e-9)
    one = cast_scan_skip(jump, RES, 0.0, 0.0, *poses[3], angles, 30.0)
    np.testing.assert_allclose(one, plain[3], atol=1e-9)


@pytest.mark.parametrize(("res", "origin"), [(0.1, (-3.7, 12.25)), (0.025, (0.0, -1.0))])
def test_skipping_matches_plain_traversal_on_speckled_grids(rng, res, origin):
    occ = room(240, 160)
    occ |= rng.uniform(size=occ.shape) < 0.002  # isolated specks: many near-miss grazes
    occ[80, 20:200] = True  # a long wall, grazed at shallow angles
    world = World.from_array(occ, res, origin=origin)
    jump = jump_map(occ, world.clearance, res)
    free = np.argwhere(~occ)
    pick = free[rng.choice(len(free), 40)]
    poses = np.column_stack(
        [
            origin[0] + (pick[:, 1] + rng.uniform(0, 1, 40)) * res,
            origin[1] + (pick[:, 0] + rng.uniform(0, 1, 40)) * res,
            rng.uniform(-math.pi, math.pi, 40),
        ]
    )
    angles = LaserSpec().angles
    plain = cast_scans(occ, res, origin[0], origin[1], poses, angles, 30.0)
    fast = cast_scans_skip(jump, res, origin[0], origin[1], poses, angles, 30.0)
    np.testing.assert_allclose(fast, plain, atol=1e-9)
