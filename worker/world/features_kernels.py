"""Grid kernels behind the floorplan features: coarsening, room shapes, the medial-axis graph,
holes of free space (loops and clutter) and visible area; vectorised numpy/scipy/skimage."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

_FOUR = ndimage.generate_binary_structure(2, 1)
_EIGHT = ndimage.generate_binary_structure(2, 2)


def boundary_edges(region: np.ndarray) -> int:
    """Number of cell edges between `region` `(H, W)` bool cells and the rest (outside counts
    as not region): the boundary length in cells."""
    padded = np.pad(region, 1)
    return int(
        np.count_nonzero(padded[1:, :] != padded[:-1, :])
        + np.count_nonzero(padded[:, 1:] != padded[:, :-1])
    )


def coarsen(mask: np.ndarray, factor: int) -> np.ndarray:
    """`mask` `(H, W)` bool in blocks of `factor` x `factor`: a block is True only when all its
    cells are (walls one cell thick survive; the grid is padded with False to fit)."""
    if factor == 1:
        return mask.copy()
    h, w = mask.shape
    hh, ww = -(-h // factor) * factor, -(-w // factor) * factor
    padded = np.zeros((hh, ww), dtype=bool)
    padded[:h, :w] = mask
    out = padded[::factor, ::factor].copy()
    for i in range(factor):  # AND of the factor^2 strided sub-grids: one pass over the cells
        for j in range(factor):
            if i or j:
                out &= padded[i::factor, j::factor]
    return out


@dataclass(frozen=True)
class RoomShapes:
    """Per room `(R,)` arrays: area [m^2], the sides [m] of the rectangle with its inertia, and
    the mean clearance [m] of its cells."""

    area_m2: np.ndarray
    major_m: np.ndarray
    minor_m: np.ndarray
    clear_mean_m: np.ndarray


def room_shapes(labels: np.ndarray, n: int, resolution: float, clear: np.ndarray) -> RoomShapes:
    """Areas, equivalent-rectangle sides and mean clearance (`clear` `(H, W)` [m]) of rooms
    1..n of `labels` `(H, W)` int.

    A rectangle of sides a >= b has second central moments a^2/12 and b^2/12 along its axes, so
    the sides are sqrt(12 * eigenvalue) of the room's cell-position covariance.
    """
    iy, ix = np.nonzero(labels)
    lab = labels[iy, ix]
    x, y = (ix + 0.5) * resolution, (iy + 0.5) * resolution
    count = np.bincount(lab, minlength=n + 1)[1:].astype(np.float64)
    if count.size == 0:
        return RoomShapes(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))

    def mean(v: np.ndarray) -> np.ndarray:
        return np.bincount(lab, weights=v, minlength=n + 1)[1:] / np.maximum(count, 1)

    mx, my = mean(x), mean(y)
    cxx = mean(x * x) - mx * mx + resolution**2 / 12  # + a cell's own spread
    cyy = mean(y * y) - my * my + resolution**2 / 12
    cxy = mean(x * y) - mx * my
    half_tr, det = 0.5 * (cxx + cyy), cxx * cyy - cxy * cxy
    disc = np.sqrt(np.maximum(half_tr * half_tr - det, 0.0))
    major = np.sqrt(12.0 * (half_tr + disc))
    minor = np.sqrt(12.0 * np.maximum(half_tr - disc, 0.0))
    return RoomShapes(count * resolution * resolution, major, minor, mean(clear[iy, ix]))


def repeated_share(shapes: RoomShapes, tolerance: float) -> float:
    """Share of rooms with a twin: another room within `tolerance` (relative) in area, major and
    minor side (repeated identical rooms confuse scan matching)."""
    n = shapes.area_m2.size
    if n < 2:
        return 0.0
    close = np.ones((n, n), dtype=bool)
    for v in (shapes.area_m2, shapes.major_m, shapes.minor_m):
        scale = np.maximum(v[:, None], v[None, :])
        close &= np.abs(v[:, None] - v[None, :]) <= tolerance * np.maximum(scale, 1e-12)
    np.fill_diagonal(close, False)
    return float(close.any(axis=1).mean())


@dataclass(frozen=True)
class MedialGraph:
    """The medial-axis (skeleton) graph of free space."""

    nodes: int  # junction clusters and dead ends
    edges: int  # branches: skeleton runs between nodes
    length_m: float  # [m] total skeleton length
    branch_mean_m: float  # [m] mean branch length
    longest_path_m: float  # [m] longest shortest path on the skeleton (double sweep)


def medial_graph(free: np.ndarray, resolution: float) -> MedialGraph:
    """Skeletonize `free` `(H, W)` bool and read its graph."""
    from skimage.morphology import skeletonize

    skel = skeletonize(free)
    nb = ndimage.convolve(skel.astype(np.uint8), np.ones((3, 3), np.uint8), mode="constant")
    nb = np.where(skel, nb - 1, 0)  # 8-neighbours on the skeleton
    junction = skel & (nb >= 3)
    n_ends = int(np.count_nonzero(skel & (nb <= 1)))
    _, n_junctions = ndimage.label(junction, structure=_EIGHT)
    branches = skel & ~ndimage.binary_dilation(junction, structure=_EIGHT)
    branch_labels, n_edges = ndimage.label(branches, structure=_EIGHT)
    branch_cells = np.bincount(branch_labels.ravel())[1:]
    steps = _step_lengths(skel)
    length = float(steps.sum() * 0.5) * resolution  # each step is counted from both ends
    cell_m = length / max(int(skel.sum()), 1)  # [m] skeleton length per skeleton cell
    branch_mean = float(branch_cells.mean()) * cell_m if n_edges else 0.0
    return MedialGraph(
        nodes=n_ends + int(n_junctions),
        edges=int(n_edges),
        length_m=length,
        branch_mean_m=branch_mean,
        longest_path_m=_longest_path(skel) * resolution,
    )


_OFFSETS = ((0, 1, 1.0), (1, 0, 1.0), (1, 1, math.sqrt(2.0)), (1, -1, math.sqrt(2.0)))


def _pairs(skel: np.ndarray):
    """Yield (index a, index b, step length [cells]) arrays of skeleton neighbour pairs."""
    h, w = skel.shape
    index = np.full((h + 2, w + 2), -1, dtype=np.int64)
    iy, ix = np.nonzero(skel)
    index[iy + 1, ix + 1] = np.arange(iy.size)
    for dy, dx, d in _OFFSETS:
        nb = index[iy + 1 + dy, ix + 1 + dx]
        keep = nb >= 0
        yield np.nonzero(keep)[0], nb[keep], d


def _step_lengths(skel: np.ndarray) -> np.ndarray:
    """Per skeleton cell, the summed length [cells] of its steps to skeleton neighbours."""
    out = np.zeros(int(skel.sum()))
    for a, b, d in _pairs(skel):
        np.add.at(out, a, d)
        np.add.at(out, b, d)
    return out


def _longest_path(skel: np.ndarray) -> float:
    """Longest shortest path [cells] on the skeleton's largest component: two Dijkstra sweeps
    (exact on a tree, a lower bound with loops)."""
    n = int(skel.sum())
    if n < 2:
        return 0.0
    rows, cols, vals = [], [], []
    for a, b, d in _pairs(skel):
        rows.append(a)
        cols.append(b)
        vals.append(np.full(a.size, d))
    graph = coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n)
    ).tocsr()
    labels, _ = ndimage.label(skel, structure=_EIGHT)
    lab = labels[skel]
    start = int(np.argmax(lab == np.argmax(np.bincount(lab)[1:]) + 1))
    far = dijkstra(graph, directed=False, indices=start)
    far[~np.isfinite(far)] = -1
    far2 = dijkstra(graph, directed=False, indices=int(np.argmax(far)))
    return float(far2[np.isfinite(far2)].max())


@dataclass(frozen=True)
class Holes:
    """Obstacles enclosed by free space."""

    loops: int  # holes of at least the loop size: loops the robot can drive around
    islands: int  # all holes
    share: float  # [-] hole area / area inside the free region's outline


def holes(free: np.ndarray, min_loop_cells: float) -> Holes:
    """The holes of `free` `(H, W)` bool (obstacle components, 8-connected, that free space
    encloses; a 4-connected region's holes are exactly its complement's 8-components)."""
    filled = ndimage.binary_fill_holes(free, structure=_FOUR)
    inside = filled & ~free
    labels, n = ndimage.label(inside, structure=_EIGHT)
    sizes = np.bincount(labels.ravel())[1:]
    return Holes(
        loops=int(np.count_nonzero(sizes >= min_loop_cells)),
        islands=int(n),
        share=float(inside.sum()) / max(float(filled.sum()), 1.0),
    )


def polygon_areas(ranges: np.ndarray) -> np.ndarray:
    """Areas [m^2] of the star polygons of `ranges` `(N, B)` [m], B rays evenly spaced over a
    full circle: sum of triangles 0.5 r_i r_(i+1) sin(2 pi / B)."""
    b = ranges.shape[1]
    return 0.5 * math.sin(2.0 * math.pi / b) * (ranges * np.roll(ranges, -1, axis=1)).sum(axis=1)
