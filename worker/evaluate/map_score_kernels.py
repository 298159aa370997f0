"""Kernels of the map-versus-floorplan score: wall cells as points, ICP, nearest distances.

The nearest-neighbour queries go through scipy's cKDTree (compiled); the rest is vectorised
numpy over all cells at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

_EIGHT = np.ones((3, 3), dtype=bool)


def wall_surface(occ: np.ndarray, free: np.ndarray) -> np.ndarray:
    """`(H, W) bool` obstacle cells of `occ` with a `free` cell among their 8 neighbours.

    The floorplan's walls as a laser can see them: the inside of a thick wall and the solid
    outside of a building are never hit by a beam, so they are not walls a map could show.
    """
    near_free = ndimage.binary_dilation(free, structure=_EIGHT)
    return occ & near_free


def cell_centres(mask: np.ndarray, resolution: float, origin: np.ndarray) -> NDArray[np.float64]:
    """`(K, 2)` [m] centres of the True cells of `mask (H, W)` (`[iy, ix]`, row 0 at the bottom)."""
    iy, ix = np.nonzero(mask)
    return np.column_stack(
        (origin[0] + (ix + 0.5) * resolution, origin[1] + (iy + 0.5) * resolution)
    ).astype(np.float64)


def transform(T: np.ndarray, xy: np.ndarray) -> NDArray[np.float64]:
    """`(K, 2)` points `xy` moved by the pose T `(3,)` [x, y, theta]: R(theta) xy + t."""
    c, s = math.cos(T[2]), math.sin(T[2])
    out = np.empty_like(xy, dtype=np.float64)
    out[:, 0] = c * xy[:, 0] - s * xy[:, 1] + T[0]
    out[:, 1] = s * xy[:, 0] + c * xy[:, 1] + T[1]
    return out


def compose(a: np.ndarray, b: np.ndarray) -> NDArray[np.float64]:
    """The pose a * b (b first, then a), both `(3,)` [x, y, theta]."""
    c, s = math.cos(a[2]), math.sin(a[2])
    theta = math.atan2(math.sin(a[2] + b[2]), math.cos(a[2] + b[2]))
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], theta])


@dataclass(frozen=True)
class IcpResult:
    """A rigid registration of source points onto target points."""

    T: NDArray[np.float64]  # (3,) [x, y, theta] the refined pose applied to the source
    iterations: int  # iterations run (0: the initial pose kept)
    pairs: int  # correspondences in the last iteration
    converged: bool  # the last update was under the tolerance


def normals(points: np.ndarray, tree: cKDTree, k: int = 7) -> NDArray[np.float64]:
    """`(M, 2)` unit normals of the wall through each of `points (M, 2)`: the direction of
    least spread of its k nearest neighbours (batched 2x2 eigen-decomposition)."""
    if len(points) < 2:
        return np.tile([1.0, 0.0], (len(points), 1))
    _, idx = tree.query(points, k=min(k, len(points)))
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)  # (M, k, 2)
    cov = np.einsum("mki,mkj->mij", nb, nb)
    _, vec = np.linalg.eigh(cov)  # ascending eigenvalues: column 0 is the normal
    return vec[:, :, 0]


def _point_to_line_step(p: np.ndarray, q: np.ndarray, n: np.ndarray) -> NDArray[np.float64]:
    """The pose dT minimising sum ((R p + t - q) . n)^2, linearised in the angle about the
    centroid of p (Chen & Medioni's point-to-plane ICP in 2D), solved in least squares."""
    c = p.mean(axis=0)
    pc, qc = p - c, q - c
    # R(a) x ~ x + a (-x_y, x_x): residual n.(p - q) + n.t + a (n_y p_x - n_x p_y)
    A = np.column_stack((n[:, 0], n[:, 1], n[:, 1] * pc[:, 0] - n[:, 0] * pc[:, 1]))
    b = -np.einsum("ij,ij->i", pc - qc, n)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    a = float(sol[2])
    ca, sa = math.cos(a), math.sin(a)
    # x -> R(a)(x - c) + c + t: the translation of the pose is c + t - R(a) c
    return np.array([c[0] + sol[0] - (ca * c[0] - sa * c[1]),
                     c[1] + sol[1] - (sa * c[0] + ca * c[1]), a])  # fmt: skip


def icp(
    source: np.ndarray,
    tree: cKDTree,
    target: np.ndarray,
    T0: np.ndarray,
    max_distances: tuple[float, ...],
    iterations: int,
    tol: float,
    min_pairs: int,
) -> IcpResult:
    """Point-to-line ICP of `source (K, 2)` onto `target (M, 2)` (indexed by `tree`) from T0.

    Point-to-point ICP stalls on grids (cells snap to the same neighbours a fraction of a cell
    off); measuring the residual along the target wall's normal lets the source slide along
    walls. Each stage of `max_distances` [m] (coarse to fine) iterates until the update moves
    the source by less than `tol` [m] or `iterations` is spent. Fewer than `min_pairs` pairs
    keep the pose reached so far.
    """
    T = np.asarray(T0, dtype=np.float64).copy()
    done, pairs, converged = 0, 0, False
    if len(source) == 0 or len(target) == 0:
        return IcpResult(T, 0, 0, False)
    n_target = normals(target, tree)
    radius = float(np.max(np.linalg.norm(source - source.mean(axis=0), axis=1)))
    for max_d in max_distances:
        converged = False
        for _ in range(iterations):
            moved = transform(T, source)
            dist, idx = tree.query(moved, distance_upper_bound=max_d)
            ok = np.isfinite(dist)
            pairs = int(np.count_nonzero(ok))
            if pairs < min_pairs:
                break
            dT = _point_to_line_step(moved[ok], target[idx[ok]], n_target[idx[ok]])
            T = compose(dT, T)
            done += 1
            # the largest displacement of a source point under the update
            if math.hypot(dT[0], dT[1]) + abs(dT[2]) * radius < tol:
                converged = True
                break
    return IcpResult(T, done, pairs, converged)


def nearest_distances(points: np.ndarray, tree: cKDTree) -> NDArray[np.float64]:
    """`(K,)` [m] distance from each of `points (K, 2)` to its nearest point in `tree`."""
    if len(points) == 0:
        return np.zeros(0)
    if tree.n == 0:
        return np.full(len(points), np.inf)
    dist, _ = tree.query(points)
    return np.asarray(dist, dtype=np.float64)


def map_cells_at(
    xy_world: np.ndarray, T_world_map: np.ndarray, map_origin: np.ndarray, map_resolution: float
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Map cell indices `(ix, iy)` of world points `(K, 2)` (may lie outside the map)."""
    inv_c, inv_s = math.cos(T_world_map[2]), math.sin(T_world_map[2])
    dx = xy_world[:, 0] - T_world_map[0]
    dy = xy_world[:, 1] - T_world_map[1]
    xm = inv_c * dx + inv_s * dy  # R^T (p_world - t)
    ym = -inv_s * dx + inv_c * dy
    mx = np.floor((xm - map_origin[0]) / map_resolution).astype(np.int64)
    my = np.floor((ym - map_origin[1]) / map_resolution).astype(np.int64)
    return mx, my


def lookup(mask: np.ndarray, mx: np.ndarray, my: np.ndarray) -> NDArray[np.bool_]:
    """`mask[my, mx]` where inside the grid, False outside."""
    h, w = mask.shape
    inside = (mx >= 0) & (mx < w) & (my >= 0) & (my < h)
    out = np.zeros(len(mx), dtype=bool)
    out[inside] = mask[my[inside], mx[inside]]
    return out


# the 4 directions across a wall, by the normal's angle in 45-degree bins: (dy, dx)
_ACROSS = ((0, 1), (1, 1), (1, 0), (1, -1))


def ridge_walls(prob: np.ndarray, occ_thresh: float, sigma_cells: float) -> NDArray[np.bool_]:
    """`(H, W) bool` occupied cells on the ridge of the hit ratio across their wall.

    Laser range noise spreads a wall's hits over a band of cells several cells thick; its
    ridge is one cell thick. The hit ratio (NaN as 0) is smoothed by a Gaussian of
    `sigma_cells`; the wall's normal at a cell is the eigenvector of the smoothed ratio's
    Hessian with the most negative eigenvalue (the direction the ratio falls off fastest);
    an occupied cell is dropped if an occupied neighbour along that normal has a higher
    smoothed ratio (non-maximum suppression, as Canny's edges, within the band: a free
    neighbour never thins a wall; ties keep both). Where the ratio falls off alike in every
    direction (a corner, a post: the Hessian's two eigenvalues within a factor of two) there
    is no normal, and the cell is kept.
    """
    p = np.nan_to_num(np.asarray(prob, dtype=np.float64), nan=0.0)
    return _ridge(p, p > occ_thresh, sigma_cells)


def density_walls(
    hits: np.ndarray, prob: np.ndarray, sigma_cells: float, min_ratio: float
) -> NDArray[np.bool_]:
    """`(H, W) bool` cells on the ridge of the beams' end-point density across their wall.

    With Gaussian range noise a wall's end points scatter symmetrically about its surface,
    so their density peaks on it; the hit ratio (hits over beams through a cell) is the
    noise's hazard rate instead, which rises *behind* the surface, so that `ridge_walls`
    puts a noisy laser's walls up to a noise sigma behind the true ones. The same ridge
    (Hessian normal, non-maximum suppression across the wall, `_ridge`) is taken of the end
    points `hits` (smoothed by `sigma_cells`) among the cells holding any, where the density
    curves down across the wall (the tails of a wall's end points, behind and in front of it,
    fall off convexly and hold no ridge) and, where it falls off alike in every direction
    (a post, a wall's end), at its peak. A ridge cell is kept where its hit ratio exceeds
    `min_ratio` (a stray end point in open floor, through which many beams passed, is not a
    wall).
    """
    h = np.asarray(hits, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        solid = np.nan_to_num(np.asarray(prob, dtype=np.float64), nan=0.0) > min_ratio
    return _ridge(h, h > 0.0, sigma_cells, concave=True) & solid


def _ridge(
    p: np.ndarray, cand: np.ndarray, sigma_cells: float, concave: bool = False
) -> NDArray[np.bool_]:
    """The cells of `cand` on the ridge of `p` (H, W) smoothed by `sigma_cells` (see
    `ridge_walls`): not below a candidate neighbour along the normal, or with no normal.
    concave: only where the smoothed `p` curves down across the normal more than it curves
    up along it, and with no normal only at a peak (down in every direction, not below any
    neighbour): a ridge, not a shoulder or the rounded end of a wall.

    Computed `_ROWS` rows at a time: every quantity but the smoothed map (kept whole for its
    maximum) is a band's, and each band reads the rows its sums reach, so the cells are the
    whole map's."""
    if not cand.any():
        return cand
    h = p.shape[0]
    s = np.empty(p.shape)
    for y0 in range(0, h, _ROWS):
        s[y0 : y0 + _ROWS] = _smooth(p, sigma_cells, (0, 0), y0, min(h, y0 + _ROWS))
    eps = 1e-9 * max(float(s.max()), 1.0)  # floating-point ties (symmetric corners)
    out = np.zeros_like(cand)
    for y0 in range(0, h, _ROWS):
        y1 = min(h, y0 + _ROWS)
        out[y0:y1] = _ridge_rows(p, s, cand, sigma_cells, concave, eps, y0, y1)
    return out


_ROWS = 256  # map rows per band of `_ridge`


def _smooth(p: np.ndarray, sigma: float, order: tuple[int, int], y0: int, y1: int) -> np.ndarray:
    """`gaussian_filter(p, sigma, order, mode="constant")[y0:y1]` from the rows its sums
    reach (scipy's radius, int(4 sigma + 0.5), and two more): each output row is the same sum
    of the same inputs in the same order, so the values are the whole map's."""
    r = int(4.0 * float(sigma) + 0.5) + 2
    a, b = max(0, y0 - r), min(p.shape[0], y1 + r)
    g = ndimage.gaussian_filter(p[a:b], sigma, order=order, mode="constant")
    return g[y0 - a : y1 - a]


def _rows_padded(
    a: np.ndarray, y0: int, y1: int, fill: float, mask: np.ndarray | None = None
) -> np.ndarray:
    """Rows y0-1 .. y1 of `a (H, W)` with a column on each side, `fill` outside `a` (and
    where `mask (H, W)` is False): the band of `np.pad(a, 1, constant_values=fill)` around
    rows y0 .. y1-1."""
    h, w = a.shape
    out = np.full((y1 - y0 + 2, w + 2), fill, dtype=a.dtype)
    lo, hi = max(0, y0 - 1), min(h, y1 + 1)
    rows = a[lo:hi] if mask is None else np.where(mask[lo:hi], a[lo:hi], fill)
    out[lo - y0 + 1 : hi - y0 + 1, 1:-1] = rows
    return out


def _ridge_rows(
    p: np.ndarray, s_all: np.ndarray, cand_all: np.ndarray, sigma_cells: float,
    concave: bool, eps: float, y0: int, y1: int,
) -> NDArray[np.bool_]:  # fmt: skip
    """`_ridge`'s rows y0 .. y1-1, given the whole smoothed map `s_all` and its `eps`."""
    s, cand = s_all[y0:y1], cand_all[y0:y1]
    if concave:
        # the Hessian by central differences of the smoothed values: the truncated Gaussian's
        # own second derivatives do not sum to zero, and along a straight wall that hair of
        # curvature can outweigh the real one across it near the peak's shoulders
        q = _rows_padded(s_all, y0, y1, 0.0)
        hyy = q[2:, 1:-1] - 2.0 * s + q[:-2, 1:-1]
        hxx = q[1:-1, 2:] - 2.0 * s + q[1:-1, :-2]
        hxy = 0.25 * (q[2:, 2:] - q[2:, :-2] - q[:-2, 2:] + q[:-2, :-2])
        del q
    else:
        hyy, hxx, hxy = (_smooth(p, sigma_cells, o, y0, y1) for o in ((2, 0), (0, 2), (1, 1)))
    half_gap = np.hypot(0.5 * (hxx - hyy), hxy)  # half the eigenvalues' difference
    lam_min = 0.5 * (hxx + hyy) - half_gap
    line = 2.0 * half_gap > 0.5 * np.abs(lam_min)  # lam_max - lam_min > |lam_min| / 2
    # angle of the larger eigenvalue's eigenvector; the normal is at right angles to it
    normal = 0.5 * np.arctan2(2.0 * hxy, hxx - hyy) + 0.5 * np.pi
    bins = np.round(normal / (0.25 * np.pi)).astype(np.int64) % 4
    del normal, hxx, hyy, hxy
    padded = _rows_padded(s_all, y0, y1, -np.inf, mask=cand_all)
    h, w = s.shape
    keep = np.zeros_like(cand)
    for b, (dy, dx) in enumerate(_ACROSS):
        fwd = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
        bwd = padded[1 - dy : 1 - dy + h, 1 - dx : 1 - dx + w]
        keep |= (bins == b) & (s >= fwd - eps) & (s >= bwd - eps)
    if concave:
        # a peak across the wall: the curvature of largest magnitude (the normal's) is
        # negative; with no normal (a post, a wall's end) a peak in every direction
        lam_max = lam_min + 2.0 * half_gap
        keep &= (lam_min < -eps) & (lam_min + lam_max < 0.0)
        peak = lam_max < -eps
        for dy, dx in _ACROSS:
            fwd = padded[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w]
            bwd = padded[1 - dy : 1 - dy + h, 1 - dx : 1 - dx + w]
            peak &= (s >= fwd - eps) & (s >= bwd - eps)
        return cand & np.where(line, keep, peak)
    return cand & (keep | ~line)


def front_walls(prob: np.ndarray, occ_thresh: float) -> NDArray[np.bool_]:
    """`(H, W) bool` occupied cells with a free (seen, not occupied) cell among their 8
    neighbours: the wall's face towards the robot, as `wall_surface` takes the floorplan's."""
    p = np.asarray(prob)
    known = ~np.isnan(p)
    occ = np.nan_to_num(p, nan=0.0) > occ_thresh
    return wall_surface(occ, known & ~occ)
