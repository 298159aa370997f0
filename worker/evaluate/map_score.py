"""The map against the floorplan: wall precision / recall, symmetric wall distance, free share.

A second measure of a run, independent of the relations: it scores the final SLAM *map*, not
the trajectory. The map frame and the world frame differ by the start pose, so the map is put
in the world by T0 (the first estimated pose onto the first ground-truth pose) and the
registration is refined by ICP of the map's occupied cell centres onto the floorplan's wall
cells, the best rigid fit the map allows. Then, with d(p, S) the distance from p to the
nearest point of S:
- precision: share of map wall cells within `tolerance` of a floorplan wall;
- recall: share of the floorplan walls the map has seen (near a known map cell) that lie
  within `tolerance` of a map wall; `wall_coverage` is the same over all floorplan walls;
- distance: (mean over map walls of d(., floorplan walls) + mean over seen floorplan walls of
  d(., map walls)) / 2, the symmetric mean nearest-neighbour (chamfer) distance [m];
- free_share: share of the reachable floorplan free space the aligned map marks free.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from worker.evaluate import map_score_kernels as k
from worker.evaluate.coverage import coverage

WALLS = ("density", "ridge", "front", "occupied")


@dataclass(frozen=True)
class MapScoreParams:
    """How the map is registered onto the floorplan and compared with it."""

    tolerance: float = 0.1  # [m] a wall cell this close to a wall of the other counts as matched
    # [m] ICP correspondence gates, coarse to fine (a bad map may start a metre off)
    icp_max_distances: tuple[float, ...] = (1.0, 0.5, 0.25)
    icp_iterations: int = 30  # per gate; 0 keeps T0 (no refinement)
    icp_tol: float = 1e-4  # [m] stop a gate once the update moves no wall cell more than this
    icp_min_pairs: int = 10  # fewer correspondences keep the pose reached so far
    seen_margin: float = 0.1  # [m] a floorplan wall this close to a known map cell was seen
    # which of the map's cells are its walls: "density" (cells on the ridge of the beams' end
    # point counts across the wall, where a noisy laser's walls really are; a map without
    # counts, OccupancyGrid.hits None, falls back to "ridge"), "ridge" (occupied cells on the
    # ridge of the hit ratio: thin, but behind the surface under range noise), "front"
    # (occupied cells facing a free cell) or "occupied" (every cell above occ_thresh)
    walls: str = "density"
    ridge_sigma_m: float = 0.05  # [m] Gaussian smoothing of the hit ratio ("ridge")
    # [m] Gaussian smoothing of the end-point counts ("density"); `for_laser_noise` matches it
    # to the laser's range noise, as a run does: a wall's end points scatter across it by
    # that sigma, and a narrower filter leaves many small peaks across the band
    density_sigma_m: float = 0.05
    # a "density" ridge cell is a wall only where more than this share of the beams through
    # it ended in it (a stray end point in open floor is not)
    density_min_ratio: float = 0.05

    def __post_init__(self) -> None:
        if self.walls not in WALLS:
            raise ValueError(f"walls must be one of {', '.join(WALLS)}, got {self.walls!r}")

    def for_laser_noise(self, sigma_m: float) -> MapScoreParams:
        """These settings with the end points smoothed by the laser's range noise `sigma_m`
        [m] (a filter matched to the scatter of a wall's end points), never below
        density_sigma_m."""
        return replace(self, density_sigma_m=max(self.density_sigma_m, float(sigma_m)))


@dataclass(frozen=True)
class MapScore:
    """The score of one map; ratios in [0, 1], None where there is nothing to take it over."""

    precision: float | None  # share of map walls within tolerance of a floorplan wall
    recall: float | None  # share of seen floorplan walls within tolerance of a map wall
    wall_coverage: float | None  # share of all floorplan walls within tolerance of a map wall
    distance_m: float | None  # [m] symmetric mean nearest-neighbour distance
    distance_map_m: float | None  # [m] mean over map walls to the floorplan walls
    distance_floorplan_m: float | None  # [m] mean over seen floorplan walls to the map walls
    free_share: float  # reachable floorplan free space the map marks free
    tolerance_m: float  # [m]
    n_map_walls: int
    n_floorplan_walls: int
    n_floorplan_walls_seen: int
    T_world_map: np.ndarray  # (3,) [x, y, theta] the refined registration
    icp_iterations: int
    icp_converged: bool
    floorplan_walls: np.ndarray  # (H, W) bool world cells: the walls compared against
    map_walls_xy: np.ndarray  # (K, 2) [m] the map's wall cell centres, registered (world frame)
    walls: str = "ridge"  # the wall extraction used (MapScoreParams.walls, or its fallback)
    # [m] its smoothing (ridge_sigma_m or density_sigma_m; None for "front" and "occupied")
    walls_sigma_m: float | None = 0.05

    def summary(self) -> dict:
        """summary.json's `map_score` section."""
        out = {
            name: getattr(self, name)
            for name in (
                "precision", "recall", "wall_coverage", "distance_m", "distance_map_m",
                "distance_floorplan_m", "free_share", "tolerance_m", "n_map_walls",
                "n_floorplan_walls", "n_floorplan_walls_seen", "icp_iterations", "icp_converged",
                "walls", "walls_sigma_m",
            )
        }  # fmt: skip
        x, y, th = (float(v) for v in self.T_world_map)
        out["alignment"] = {"x": x, "y": y, "theta": th}
        return out


def start_alignment(pose_est0: np.ndarray, pose_gt0: np.ndarray) -> np.ndarray:
    """T_world_map `(3,)` that maps the first estimated pose onto the first ground-truth pose."""
    th = float(pose_gt0[2] - pose_est0[2])
    c, s = np.cos(th), np.sin(th)
    x = pose_gt0[0] - (c * pose_est0[0] - s * pose_est0[1])
    y = pose_gt0[1] - (s * pose_est0[0] + c * pose_est0[1])
    return np.array([x, y, np.arctan2(np.sin(th), np.cos(th))])


def floorplan_walls(occ: np.ndarray, reachable: np.ndarray) -> np.ndarray:
    """`(H, W) bool` the walls of the floorplan a robot in `reachable` can see."""
    return k.wall_surface(occ, reachable)


def walls_used(grid, p: MapScoreParams = MapScoreParams()) -> str:
    """The wall extraction `map_walls` applies to `grid`: p.walls, but "ridge" for "density"
    on a map without end-point counts."""
    if p.walls == "density" and getattr(grid, "hits", None) is None:
        return "ridge"
    return p.walls


def map_walls(grid, p: MapScoreParams = MapScoreParams()) -> np.ndarray:
    """`(H, W) bool` the cells of `grid` (an OccupancyGrid) taken as its walls, by `p.walls`."""
    if p.walls == "occupied":
        return grid.occupied
    if p.walls == "front":
        return k.front_walls(grid.prob, grid.occ_thresh)
    if walls_used(grid, p) == "density":
        sigma = p.density_sigma_m / grid.resolution
        return k.density_walls(grid.hits, grid.prob, sigma, p.density_min_ratio)
    return k.ridge_walls(grid.prob, grid.occ_thresh, p.ridge_sigma_m / grid.resolution)


def score_map(
    occ: np.ndarray,
    world_resolution: float,
    world_origin: np.ndarray,
    reachable: np.ndarray,
    grid,
    T0: np.ndarray,
    p: MapScoreParams = MapScoreParams(),
) -> MapScore:
    """Score `grid` (a worker.slam.grid.OccupancyGrid, map frame) against the world.

    occ, reachable: `(H, W) bool` world grids (obstacle; reachable free space, as
    worker.evaluate.coverage.reachable_free gives it); T0: T_world_map to start ICP from.
    """
    world_origin = np.asarray(world_origin, dtype=np.float64)
    fp_walls = floorplan_walls(occ, reachable)
    fp_xy = k.cell_centres(fp_walls, world_resolution, world_origin)
    used = walls_used(grid, p)
    map_xy = k.cell_centres(map_walls(grid, p), grid.resolution, grid.origin)
    fp_tree = cKDTree(fp_xy)
    reg = _register(map_xy, fp_tree, fp_xy, np.asarray(T0, dtype=np.float64), p)
    T = reg.T
    map_w = k.transform(T, map_xy)
    d_map = k.nearest_distances(map_w, fp_tree)
    margin = int(np.ceil(p.seen_margin / grid.resolution - 1e-9))
    known = grid.known
    if margin > 0:
        known = ndimage.binary_dilation(known, structure=np.ones((3, 3), bool), iterations=margin)
    seen = k.lookup(known, *k.map_cells_at(fp_xy, T, grid.origin, grid.resolution))
    d_fp_all = k.nearest_distances(fp_xy, cKDTree(map_w))
    d_fp = d_fp_all[seen]
    free = coverage(reachable, world_resolution, world_origin, grid.prob, grid.resolution,
                    grid.origin, grid.occ_thresh, T)  # fmt: skip
    tol = p.tolerance
    mean_map = _mean(d_map)
    mean_fp = _mean(d_fp)
    return MapScore(
        precision=_share(d_map, tol),
        recall=_share(d_fp, tol),
        wall_coverage=_share(d_fp_all, tol),
        distance_m=None if mean_map is None or mean_fp is None else 0.5 * (mean_map + mean_fp),
        distance_map_m=mean_map,
        distance_floorplan_m=mean_fp,
        free_share=float(free),
        tolerance_m=tol,
        n_map_walls=len(map_xy),
        n_floorplan_walls=len(fp_xy),
        n_floorplan_walls_seen=int(np.count_nonzero(seen)),
        T_world_map=T,
        icp_iterations=reg.iterations,
        icp_converged=reg.converged,
        floorplan_walls=fp_walls,
        map_walls_xy=map_w,
        walls=used,
        walls_sigma_m={"density": p.density_sigma_m, "ridge": p.ridge_sigma_m}.get(used),
    )


def _register(
    map_xy: np.ndarray, fp_tree: cKDTree, fp_xy: np.ndarray, T0: np.ndarray, p: MapScoreParams
) -> k.IcpResult:
    """ICP from T0, kept only if it brings the map's walls closer to the floorplan's.

    ICP minimises distances along the walls' normals; the score measures distances to the
    nearest wall cell. On a map that already sits on its floorplan (cells of its walls a cell
    in front of or behind the plan's), ICP can trade one for the other; the registration
    scored is the one of the two with the smaller mean distance, each capped at the widest
    ICP gate so that a few stray cells do not decide.
    """
    start = k.IcpResult(T0, 0, 0, False)
    if p.icp_iterations <= 0 or len(map_xy) == 0:
        return start
    reg = k.icp(map_xy, fp_tree, fp_xy, T0, p.icp_max_distances, p.icp_iterations,
                p.icp_tol, p.icp_min_pairs)  # fmt: skip
    cap = max(p.icp_max_distances)

    def cost(T: np.ndarray) -> float:
        return float(np.mean(np.minimum(k.nearest_distances(k.transform(T, map_xy), fp_tree), cap)))

    return reg if cost(reg.T) < cost(T0) else start


def _share(d: np.ndarray, tol: float) -> float | None:
    # the tolerance is compared with a hair of slack: cell centres a whole number of cells
    # apart come out of floating point a few ulps off
    return float(np.mean(d <= tol + 1e-9)) if len(d) else None


def _mean(d: np.ndarray) -> float | None:
    return float(np.mean(d)) if len(d) and np.all(np.isfinite(d)) else None
