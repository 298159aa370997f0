"""How well a SLAM map's walls overlap a floorplan's walls (both in the world frame)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from worker.slam.grid import OccupancyGrid


@dataclass(frozen=True)
class WallOverlap:
    """precision: share of the map's occupied cells within tol of a floorplan wall.
    recall: share of the floorplan's wall surface cells inside the map's seen area (within
    tol of a seen cell) that have an occupied map cell within tol.
    n_occupied, n_surface: the cell counts behind each share. tol [m]."""

    precision: float
    recall: float
    n_occupied: int
    n_surface: int
    tol: float


def _centres(mask: np.ndarray, res: float, origin: np.ndarray) -> np.ndarray:
    iy, ix = np.nonzero(mask)
    return np.column_stack([origin[0] + (ix + 0.5) * res, origin[1] + (iy + 0.5) * res])


def _lookup(values: np.ndarray, xy: np.ndarray, res: float, origin, fill) -> np.ndarray:
    """values[iy, ix] at world points (N, 2); `fill` outside the grid."""
    ix = np.floor((xy[:, 0] - origin[0]) / res).astype(np.int64)
    iy = np.floor((xy[:, 1] - origin[1]) / res).astype(np.int64)
    h, w = values.shape
    ok = (ix >= 0) & (iy >= 0) & (ix < w) & (iy < h)
    out = np.full(len(xy), fill, dtype=values.dtype)
    out[ok] = values[iy[ok], ix[ok]]
    return out


def wall_overlap(
    grid: OccupancyGrid,
    occ: np.ndarray,
    resolution: float,
    origin: np.ndarray,
    tol: float = 0.1,
) -> WallOverlap:
    """Compare a SLAM map with a floorplan occ (H, W) bool [iy, ix] bottom row first.

    The map must be in the floorplan's frame (the SLAM map frame is the odometry frame at the
    first scan, which the simulator starts at the true pose). tol [m]: e.g. two cells.
    """
    origin = np.asarray(origin, dtype=np.float64)
    occ = np.asarray(occ, dtype=bool)
    # precision: distance from each occupied map cell to the nearest floorplan wall cell
    d_wall = ndimage.distance_transform_edt(~occ) * resolution
    pts = _centres(grid.occupied, grid.resolution, grid.origin)
    near = _lookup(d_wall, pts, resolution, origin, np.inf) <= tol + 0.5 * grid.resolution
    precision = float(near.mean()) if len(pts) else 0.0
    # recall: wall cells touching free space, inside the map's seen area
    surface = occ & ndimage.binary_dilation(~occ)
    spts = _centres(surface, resolution, origin)
    d_seen = ndimage.distance_transform_edt(~grid.known) * grid.resolution
    d_occ = ndimage.distance_transform_edt(~grid.occupied) * grid.resolution
    seen = _lookup(d_seen, spts, grid.resolution, grid.origin, np.inf) <= tol
    hit = _lookup(d_occ, spts[seen], grid.resolution, grid.origin, np.inf) <= tol
    recall = float(hit.mean()) if seen.any() else 0.0
    return WallOverlap(precision, recall, int(len(pts)), int(seen.sum()), tol)
