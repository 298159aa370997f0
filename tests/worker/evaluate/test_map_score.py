"""The map-versus-floorplan score on hand-made rooms whose distances are counted by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.evaluate import map_score_kernels as k
from worker.evaluate.map_score import MapScoreParams, score_map, start_alignment
from worker.slam.grid import OccupancyGrid

RES = 0.05  # [m]


def ring(w: int, h: int) -> np.ndarray:
    """(h, w) bool: a one-cell wall around the grid's edge."""
    occ = np.zeros((h, w), bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    return occ


def room_with_pillar() -> np.ndarray:
    """A 4 m x 3 m room (one-cell walls) with a 0.5 m pillar off the centre: no symmetry, so
    one rigid pose alone fits it."""
    occ = ring(82, 62)
    occ[15:25, 20:30] = True
    occ[40:45, 60:62] = True
    return occ


def seen_surface(occ: np.ndarray) -> np.ndarray:
    """Obstacle cells with a free cell among their 8 neighbours (what beams can hit)."""
    free = np.pad(~occ, 1, constant_values=False)
    h, w = occ.shape
    near = np.zeros_like(occ)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near |= free[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
    return occ & near


def perfect_map(occ: np.ndarray) -> OccupancyGrid:
    """The floorplan as a laser maps it, in the world frame: the walls' surfaces occupied,
    free cells free, the inside of the pillar never seen."""
    prob = np.where(occ, np.nan, 0.0).astype(np.float32)
    prob[seen_surface(occ)] = 1.0
    return OccupancyGrid(prob, RES, np.zeros(2))


def test_a_perfect_map_scores_precision_and_recall_one_and_distance_zero():
    occ = room_with_pillar()
    s = score_map(occ, RES, np.zeros(2), ~occ, perfect_map(occ), np.zeros(3))
    assert (s.precision, s.recall, s.wall_coverage) == (1.0, 1.0, 1.0)
    assert s.distance_m == pytest.approx(0.0, abs=1e-12)
    assert s.free_share == 1.0
    # inner wall surface only: the map's walls are the floorplan's walls, cell for cell
    assert s.n_map_walls == s.n_floorplan_walls == s.n_floorplan_walls_seen


@pytest.mark.parametrize("offset", [(0.12, -0.07, 0.03), (-0.3, 0.2, -0.05), (0.0, 0.0, 0.08)])
def test_a_map_started_off_by_a_known_offset_registers_back(offset):
    occ = room_with_pillar()
    s = score_map(occ, RES, np.zeros(2), ~occ, perfect_map(occ), np.array(offset))
    np.testing.assert_allclose(s.T_world_map, [0.0, 0.0, 0.0], atol=1e-6)
    assert (s.precision, s.recall) == (1.0, 1.0)
    assert s.distance_m == pytest.approx(0.0, abs=1e-6)
    assert s.icp_converged


def test_a_map_in_its_own_frame_is_placed_by_its_pose_and_refined():
    """The map frame is the world frame moved by T = (1.0, 0.5, +90 deg): world point
    w = R m + t, so the map array is the world's turned a quarter and its origin follows."""
    occ = room_with_pillar()
    h, w = occ.shape
    tx, ty = 1.0, 0.5
    prob = perfect_map(occ).prob.T[::-1, :]  # A[a, b] = world[b, w-1-a]
    # map cell (0, 0) is world cell (ix = w-1, iy = 0): m = R^T (w - t) = (wy - ty, tx - wx)
    grid = OccupancyGrid(prob, RES, np.array([-ty, tx - w * RES]))
    T_true = np.array([tx, ty, math.pi / 2])
    for T0 in (T_true, T_true + [0.1, -0.1, 0.04]):
        s = score_map(occ, RES, np.zeros(2), ~occ, grid, T0)
        np.testing.assert_allclose(s.T_world_map, T_true, atol=1e-6)
        assert (s.precision, s.recall, s.free_share) == (1.0, 1.0, 1.0)
        assert s.distance_m == pytest.approx(0.0, abs=1e-6)


def test_a_wall_drawn_too_far_gives_the_distances_counted_by_hand():
    """Floorplan: a 40 x 30 cell ring. Map: a 46 x 30 cell ring (its right wall 6 cells too far
    right), not registered (ICP off). Distances in cells:
    - map -> floorplan: the 6 extra cells of the top and the bottom row are 1..6 from the
      floorplan's corner; the map's right wall (28 cells between the rows) is 6 from the
      floorplan's; the other 2*40 + 30 - 2 ... map cells lie on the floorplan: 0.
      148 map cells, sum 2 * 21 + 28 * 6 = 210; beyond 2 cells (0.1 m): 2 * 4 + 28 = 36.
    - floorplan -> map: the floorplan's right wall cells y = 1..28 are min(y, 29 - y, 6)
      from the map (its top/bottom rows pass through the floorplan's corners, its right wall
      6 away): sum 15 + 18 * 6 + 15 = 138 over 136 cells; beyond 2 cells: 28 - 4 = 24.
    """
    fp = ring(40, 30)
    grid = perfect_map(ring(46, 30))
    p = MapScoreParams(icp_iterations=0)
    s = score_map(fp, RES, np.zeros(2), ~fp, grid, np.zeros(3), p)
    assert (s.n_map_walls, s.n_floorplan_walls, s.n_floorplan_walls_seen) == (148, 136, 136)
    assert s.distance_map_m == pytest.approx(RES * 210 / 148)
    assert s.distance_floorplan_m == pytest.approx(RES * 138 / 136)
    assert s.distance_m == pytest.approx(0.5 * RES * (210 / 148 + 138 / 136))
    assert s.precision == pytest.approx(112 / 148)
    assert s.recall == pytest.approx(112 / 136)
    assert s.free_share == 1.0


def test_walls_the_map_never_saw_count_against_wall_coverage_not_recall():
    """The map knows only the left half (x < 1.0 m) of a 40 x 30 ring, seen perfectly."""
    fp = ring(40, 30)
    prob = np.where(fp, 1.0, 0.0).astype(np.float32)
    prob[:, 20:] = np.nan
    s = score_map(fp, RES, np.zeros(2), ~fp, OccupancyGrid(prob, RES, np.zeros(2)), np.zeros(3),
                  MapScoreParams(icp_iterations=0, seen_margin=0.0))  # fmt: skip
    # map: left wall 30 + 2 rows of 19 = 68 cells; floorplan 136, seen the same 68
    assert (s.n_map_walls, s.n_floorplan_walls_seen) == (68, 68)
    assert (s.precision, s.recall) == (1.0, 1.0)
    # unseen floorplan cells: x = 20..38 on two rows within 2 cells of x = 19 are x = 20, 21
    # (2 each), the right wall's 30 are far: matched 68 + 2 * 2 = 72 of 136
    assert s.wall_coverage == pytest.approx(72 / 136)
    # reachable interior 38 x 28; the map marks free x = 1..19 of it: 19 of 38 columns
    assert s.free_share == pytest.approx(19 / 38)


def test_start_alignment_maps_the_first_estimate_onto_the_first_ground_truth():
    est0 = np.array([0.0, 0.0, 0.0])
    gt0 = np.array([2.0, 3.0, math.pi / 2])
    np.testing.assert_allclose(start_alignment(est0, gt0), gt0)
    # est0 = (1, 0, 0) must land on gt0: t = gt0.xy - R(pi/2) (1, 0) = (2, 2)
    np.testing.assert_allclose(start_alignment(np.array([1.0, 0, 0]), gt0), [2.0, 2.0, math.pi / 2])


def test_an_empty_map_scores_none_but_free_share_zero():
    fp = ring(20, 20)
    grid = OccupancyGrid(np.full((20, 20), np.nan, np.float32), RES, np.zeros(2))
    s = score_map(fp, RES, np.zeros(2), ~fp, grid, np.zeros(3))
    assert (s.precision, s.recall, s.distance_m) == (None, None, None)
    assert s.wall_coverage == 0.0
    assert s.free_share == 0.0


def blurred_ring() -> np.ndarray:
    """A 40 x 30 ring map as range noise draws it: the wall cells hit 80 % of the time, the
    ring one cell inside 30 % (above the grid's 25 %: occupied too), the rest free."""
    prob = np.zeros((30, 40), np.float32)
    prob[1:-1, 1:-1] = 0.3
    prob[2:-2, 2:-2] = 0.0
    prob[ring(40, 30)] = 0.8
    return prob


def test_a_wall_blurred_by_noise_is_thinned_to_its_ridge():
    """Every occupied map cell counts as wall: the inner ring's 2 * 38 + 2 * 26 = 128 cells lie
    one cell (0.05 m) inside the floorplan's 136, so map -> plan is 0.05 * 128 / 264. The ridge
    (the map padded by two unknown cells, as behind a real wall) drops the inner ring's
    straight runs: across the wall, their outer neighbour's smoothed ratio is higher. At each
    corner the inner corner cell (1, 1) stays and outranks the two outer cells beside it,
    (0, 1) and (1, 0): with a 3 x 3 Gaussian of sigma 1 cell (weights 1, e^-0.5, e^-1), (1, 1)
    has 0.3 + 0.607 * 2.2 + 0.368 * 2.4 = 2.52 against 0.8 + 0.607 * 1.9 + 0.368 * 1.1 = 2.36.
    So 136 - 8 + 4 = 132 map walls; the 4 kept inner corners are 0.05 m from the plan and the
    8 dropped plan cells 0.05 m from the map's corner cells."""
    fp = ring(40, 30)
    grid = OccupancyGrid(blurred_ring(), RES, np.zeros(2))
    occupied = score_map(fp, RES, np.zeros(2), ~fp, grid, np.zeros(3),
                         MapScoreParams(icp_iterations=0, walls="occupied"))  # fmt: skip
    assert occupied.n_map_walls == 264
    assert occupied.distance_map_m == pytest.approx(RES * 128 / 264)
    padded = OccupancyGrid(
        np.pad(blurred_ring(), 2, constant_values=np.nan), RES, -2 * RES * np.ones(2)
    )
    s = score_map(fp, RES, np.zeros(2), ~fp, padded, np.zeros(3), MapScoreParams(icp_iterations=0))
    assert s.n_map_walls == 132
    assert s.distance_map_m == pytest.approx(RES * 4 / 132)
    assert s.distance_floorplan_m == pytest.approx(RES * 8 / 136)
    assert (s.precision, s.recall) == (1.0, 1.0)


def test_the_front_of_a_blurred_wall_is_its_face_towards_free_space():
    """'front' keeps the occupied cells next to a free cell: the inner ring (128 cells, all
    0.05 m inside) and the outer ring's cells that touch a free cell diagonally: none, the
    inner ring separates them, so map -> plan is 0.05 m exactly."""
    fp = ring(40, 30)
    grid = OccupancyGrid(blurred_ring(), RES, np.zeros(2))
    s = score_map(fp, RES, np.zeros(2), ~fp, grid, np.zeros(3),
                  MapScoreParams(icp_iterations=0, walls="front"))  # fmt: skip
    assert s.n_map_walls == 128
    assert s.distance_map_m == pytest.approx(RES)
    assert (s.walls, s.walls_sigma_m) == ("front", None)  # no smoothing to report
    assert "walls_sigma_m" in s.summary() and s.summary()["walls_sigma_m"] is None


def test_an_unknown_wall_extraction_is_refused():
    with pytest.raises(ValueError, match="walls must be one of"):
        MapScoreParams(walls="skeleton")


def noisy_wall(sigma_cells: float, surface: int, rows: int = 40, cols: int = 60):
    """A wall across the grid whose surface is the centre of column `surface`, seen by 1000
    beams a row from the left with Gaussian range noise of `sigma_cells`: (hits, prob), as
    GMapping counts them. A column's hits are the beams ending in it, N (Phi(b) - Phi(a))
    over its edges a, b in sigmas from the surface; its visits the beams reaching its near
    edge, N (1 - Phi(a)); the ratio is the noise's hazard rate, which only rises with depth."""
    from scipy.stats import norm

    i = np.arange(cols)
    a = (i - 0.5 - surface) / sigma_cells
    b = (i + 0.5 - surface) / sigma_cells
    hits = 1000.0 * (norm.cdf(b) - norm.cdf(a))
    visits = 1000.0 * norm.sf(a)
    prob = np.where(visits > 1e-9, hits / np.maximum(visits, 1e-300), np.nan)
    return (np.tile(hits, (rows, 1)).astype(np.float32),
            np.tile(prob, (rows, 1)).astype(np.float32))  # fmt: skip


def test_the_end_point_density_puts_a_noisy_wall_on_its_surface_where_the_ratio_does_not():
    """Range noise of 6 cells (0.3 m at 0.05 m): the end points' density peaks on the surface
    (a Gaussian's mode is its mean), so the density ridge is column 20 exactly; the hit ratio
    passes 0.25 about one sigma behind it and keeps rising, so its ridge lies further back."""
    hits, prob = noisy_wall(6.0, 20)
    inner = slice(5, 35)  # rows away from the grid's ends, where the wall ends
    dens = k.density_walls(hits, prob, 1.0, 0.05)[inner]
    assert np.array_equal(np.flatnonzero(dens.any(axis=0)), [20]) and dens[:, 20].all()
    ridge = k.ridge_walls(prob, 0.25, 1.0)[inner]
    assert ridge.any() and np.flatnonzero(ridge.any(axis=0)).min() >= 20 + 4


def test_the_map_score_takes_a_noisy_walls_surface_from_the_hit_counts():
    """The same wall scored against its floorplan (solid from column 20 on): on the surface
    with the counts (walls 'density'), 0.2 m and more behind it by the ratio alone (a map
    with no counts falls back to the ridge, and says so): outside the 0.1 m tolerance, every
    cell."""
    hits, prob = noisy_wall(6.0, 20)
    occ = np.zeros(prob.shape, bool)
    occ[:, 20:] = True
    p = MapScoreParams(icp_iterations=0)
    with_counts = OccupancyGrid(prob, RES, np.zeros(2), hits=hits)
    s = score_map(occ, RES, np.zeros(2), ~occ, with_counts, np.zeros(3), p)
    assert s.walls == "density" and s.summary()["walls"] == "density"
    # every map wall on the surface; the wall's last rows, where the counts stop at the
    # grid's edge, curve down along it and hold no ridge (2 of its 40 cells left unmatched)
    assert s.precision == 1.0 and s.distance_map_m == pytest.approx(0.0, abs=1e-12)
    assert s.recall >= 0.95
    r = score_map(occ, RES, np.zeros(2), ~occ, OccupancyGrid(prob, RES, np.zeros(2)),
                  np.zeros(3), p)  # fmt: skip
    assert r.walls == "ridge" and r.distance_map_m >= 0.2
    assert r.recall == 0.0 and r.precision == 0.0


def test_hits_of_another_shape_than_the_map_are_refused():
    with pytest.raises(ValueError, match="hits must have the map's shape"):
        OccupancyGrid(np.zeros((3, 4)), RES, np.zeros(2), hits=np.zeros((4, 3)))


def test_a_runs_map_score_smooths_the_end_points_by_the_lasers_range_noise():
    """A filter matched to the end points' scatter; never narrower than the default."""
    p = MapScoreParams()
    assert p.for_laser_noise(0.3).density_sigma_m == 0.3
    assert p.for_laser_noise(0.0).density_sigma_m == p.density_sigma_m == 0.05
    assert p.for_laser_noise(0.3).ridge_sigma_m == p.ridge_sigma_m
