"""Grid analysis behind the world facts: clearance, connected free regions, start pose choice."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

# 4-connectivity: a robot cannot pass between two diagonally touching wall cells.
_FOUR = ndimage.generate_binary_structure(2, 1)


def clearance_map(occ: np.ndarray, resolution: float) -> np.ndarray:
    """Distance [m] from each free cell's centre to the nearest obstacle, `(H, W)` float64.

    The nearest obstacle cell's centre distance minus half a cell (its near face, for axis
    neighbours). Outside the grid counts as obstacle. Occupied cells read 0.
    """
    free = np.pad(~occ, 1, constant_values=False)
    dist_cells = ndimage.distance_transform_edt(free)[1:-1, 1:-1]
    clearance = (dist_cells - 0.5) * resolution
    clearance[occ] = 0.0
    return clearance


def free_regions(occ: np.ndarray) -> tuple[np.ndarray, int]:
    """Label 4-connected free regions: `(labels (H, W) int32, n_regions)`, 0 = occupied."""
    labels, n = ndimage.label(~occ, structure=_FOUR)
    return labels.astype(np.int32), int(n)


def border_labels(labels: np.ndarray) -> set[int]:
    """Labels of the regions that touch the image border."""
    edge = np.concatenate([labels[0, :], labels[-1, :], labels[:, 0], labels[:, -1]])
    return {int(v) for v in np.unique(edge) if v != 0}


def main_region(labels: np.ndarray, n_regions: int) -> tuple[int, bool]:
    """The largest free region not touching the border (an enclosed one), else the largest.

    Returns `(label, enclosed)`; label 0 when there is no free cell at all.
    """
    if n_regions == 0:
        return 0, False
    sizes = np.bincount(labels.ravel(), minlength=n_regions + 1)
    sizes[0] = 0
    touching = border_labels(labels)
    enclosed = sizes.copy()
    for lab in touching:
        enclosed[lab] = 0
    if enclosed.max() > 0:
        return int(np.argmax(enclosed)), True
    return int(np.argmax(sizes)), False


def choose_start_pose(
    clearance: np.ndarray, labels: np.ndarray, region: int, resolution: float, origin: np.ndarray
) -> np.ndarray:
    """The centre of the cell of largest clearance in `region` (first in row order on ties).

    Returns `(3,)` [x, y, theta] with theta = 0.
    """
    masked = np.where(labels == region, clearance, -1.0)
    iy, ix = np.unravel_index(int(np.argmax(masked)), masked.shape)
    return np.array([origin[0] + (ix + 0.5) * resolution, origin[1] + (iy + 0.5) * resolution, 0.0])


def footprint_radius(footprint_m: float) -> float:
    """Radius [m] of the circle around a square footprint of side `footprint_m`."""
    return footprint_m * math.sqrt(0.5)
