"""Correlative scan matching of a scan against a map of points: branch-and-bound over a
max-pooled pyramid (Cartographer), a hill climb on the interpolated grid, then point-to-line
ICP (the grid alone resolves a pose to about a cell; walls sampled by the map's points
resolve it to millimetres)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from worker.slam.graph.match_kernels import branch_and_bound, max_pyramid, refine, smear_grid
from worker.slam.graph.nodes import place

ICP_MAX_DIST = 0.15  # [m] pairs farther apart are not used by the ICP refinement
ICP_PRIOR_SIGMA = (0.05, 0.02)  # [m], [rad] what holds the unconstrained directions


@dataclass(frozen=True)
class MatchResult:
    """The best pose found and its response (mean smeared-grid value at the scan's points)."""

    pose: np.ndarray  # (3,) [x, y, theta] map frame
    score: float  # [0, 1]; -1 when no pose reached the minimum score


def angular_step(points: np.ndarray, res: float) -> float:
    """[rad] the angle that moves the farthest point by about one cell (Cartographer:
    acos(1 - res^2 / (2 d_max^2)))."""
    d_max = float(np.sqrt((points**2).sum(axis=1).max())) if len(points) else 1.0
    d_max = max(d_max, 2.0 * res)
    return math.acos(1.0 - res * res / (2.0 * d_max * d_max))


class PointMap:
    """Map points (K, 2) [m] rasterised around a region as a smeared grid and its pyramid."""

    def __init__(
        self,
        points: np.ndarray,
        res: float,
        sigma: float,
        depth: int,
        bounds: tuple[float, float, float, float] | None = None,
        normals: np.ndarray | None = None,
    ):
        """bounds: (x0, y0, x1, y1) [m] the region kept (None = the points' extent); the grid
        extends a kernel radius past it. normals: (K, 2) unit normals of the points; given,
        a match ends with point-to-line ICP against the points."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        if bounds is None:
            lo = pts.min(axis=0) if len(pts) else np.zeros(2)
            hi = pts.max(axis=0) if len(pts) else np.zeros(2)
        else:
            lo, hi = np.array(bounds[:2]), np.array(bounds[2:])
        pad = 2.0 * sigma + 2.0 * res
        self.res = float(res)
        self.origin = np.floor((lo - pad) / res) * res
        w = int(math.ceil((hi[0] + pad - self.origin[0]) / res)) + 1
        h = int(math.ceil((hi[1] + pad - self.origin[1]) / res)) + 1
        ox, oy = float(self.origin[0]), float(self.origin[1])
        self.grid = smear_grid(pts, ox, oy, self.res, max(h, 1), max(w, 1), float(sigma))
        self.pyramid = max_pyramid(self.grid, int(depth))
        self._tree = cKDTree(pts) if normals is not None and len(pts) >= 10 else None
        self._normals = normals

    def match(
        self,
        points: np.ndarray,
        prior: np.ndarray,
        linear_half: float,
        angular_half: float,
        min_score: float,
        dist_penalty: tuple[float, float] = (0.0, 1.0),
        angle_penalty: tuple[float, float] = (0.0, 1.0),
        exclude: tuple[float, float, float] | None = None,
        prior_information: np.ndarray | None = None,
    ) -> MatchResult:
        """Best pose of the scan `points` (M, 2) [m, robot frame] within +-linear_half [m] and
        +-angular_half [rad] of `prior` (3,); its score, or -1 below min_score.

        dist_penalty, angle_penalty: Karto's (variance [m^2 | rad^2], minimum) penalties on
        leaving the prior; a variance <= 0 is none (Karto's loop closure matches unpenalised).
        exclude: (x, y, radius) [m]: poses whose xy lies within this disc are not candidates.
        prior_information: (3, 3) the prior's information matrix [1/m^2, 1/rad^2] (the
        odometry's, for the front end); given, the ICP's pose is fused with the prior by
        their information (`fuse_with_prior`): what the walls leave free (a corridor's
        length) comes from the prior instead of wherever the flat response put it.
        """
        prior = np.asarray(prior, dtype=np.float64)
        if len(points) == 0:
            return MatchResult(prior.copy(), -1.0)
        step = angular_step(points, self.res)
        n_ang = int(math.ceil(angular_half / step))
        angles = prior[2] + step * np.arange(-n_ang, n_ang + 1, dtype=np.float64)
        window = max(0, int(round(linear_half / self.res)))
        ox, oy = float(self.origin[0]), float(self.origin[1])
        if exclude is None:
            excl = np.array([0.0, 0.0, -1.0])
        else:  # in cells relative to the prior
            excl = np.array([(exclude[0] - prior[0]) / self.res, (exclude[1] - prior[1]) / self.res,
                             exclude[2] / self.res])  # fmt: skip
        dpen = np.array(dist_penalty, dtype=np.float64)
        apen = np.array(angle_penalty, dtype=np.float64)
        score, theta, dx, dy = branch_and_bound(
            self.pyramid, ox, oy, self.res, points, prior, window, angles, float(min_score),
            dpen, apen, excl,
        )  # fmt: skip
        if score < 0:
            return MatchResult(prior.copy(), -1.0)
        coarse = np.array([prior[0] + dx * self.res, prior[1] + dy * self.res, theta])
        # the branch-and-bound optimum is one cell and one angular step coarse: hill-climb from
        # it on the bilinearly interpolated grid; the response stays the cell score
        pose, _ = refine(
            self.grid, ox, oy, self.res, points, coarse, 0.5 * self.res, step, 3,
            prior, dpen, apen, window * self.res + 1e-9, n_ang * step + 1e-9,
        )  # fmt: skip
        return MatchResult(self._polish(points, pose, step, prior, prior_information), float(score))

    def _polish(
        self,
        points: np.ndarray,
        pose: np.ndarray,
        step: float,
        prior: np.ndarray,
        prior_information: np.ndarray | None,
    ) -> np.ndarray:
        """The grid's pose (3,) polished by point-to-line ICP against the map's points (when
        it keeps normals), fused with the prior when its information is given."""
        if self._tree is None:
            return pose
        fine, info = icp_point_to_line(
            points, pose, self._tree, self._normals, ICP_MAX_DIST, ICP_PRIOR_SIGMA
        )
        # trust ICP within a cell and an angular step of the grid's answer only
        if np.hypot(*(fine[:2] - pose[:2])) < self.res and abs(fine[2] - pose[2]) < step:
            pose = fine
            if prior_information is not None:
                pose = fuse_with_prior(pose, info, prior, prior_information)
        return pose


def icp_point_to_line(
    points: np.ndarray,
    pose: np.ndarray,
    tree: cKDTree,
    map_normals: np.ndarray,
    max_dist: float,
    prior_sigma: tuple[float, float],
    iterations: int = 6,
) -> tuple[np.ndarray, np.ndarray]:
    """Refine pose (3,) of the scan points (M, 2) [robot frame] against the map points of
    `tree` with their unit normals (K, 2): Gauss-Newton on sum (n . (R p + t - q))^2 over
    pairs closer than max_dist [m], plus a prior holding the start pose with sigmas
    (xy [m], theta [rad]) so that directions the walls leave free (a corridor's length) stay
    where the correlative search put them. Returns the refined pose (3,) and the walls'
    information about it (3, 3) (J^T J / sigma_r^2 of the pairs at the last step, the prior
    left out; zero when too few points pair and the start pose is returned)."""
    x = np.array(pose, dtype=np.float64, copy=True)
    start = x.copy()
    map_pts = tree.data
    w_prior = np.array([1.0 / prior_sigma[0] ** 2] * 2 + [1.0 / prior_sigma[1] ** 2])
    for _ in range(iterations):
        c, s = np.cos(x[2]), np.sin(x[2])
        px = x[0] + c * points[:, 0] - s * points[:, 1]
        py = x[1] + s * points[:, 0] + c * points[:, 1]
        dist, idx = tree.query(np.column_stack([px, py]), distance_upper_bound=max_dist)
        ok = np.isfinite(dist)
        if ok.sum() < 10:
            return np.array(pose, dtype=np.float64, copy=True), np.zeros((3, 3))
        q, n = map_pts[idx[ok]], map_normals[idx[ok]]
        keep = (n**2).sum(axis=1) > 0.5
        q, n = q[keep], n[keep]
        ex, ey = px[ok][keep], py[ok][keep]
        r = n[:, 0] * (ex - q[:, 0]) + n[:, 1] * (ey - q[:, 1])
        # d(R p)/d theta = (-(y - ty), x - tx) of the placed point
        jt = n[:, 0] * -(ey - x[1]) + n[:, 1] * (ex - x[0])
        jac = np.column_stack([n[:, 0], n[:, 1], jt])
        sigma_r = 0.5 * max_dist  # residual scale: the pairing distance
        info = jac.T @ jac / sigma_r**2
        h = info + np.diag(w_prior)
        d_prior = x - start
        d_prior[2] = (d_prior[2] + np.pi) % (2 * np.pi) - np.pi
        g = jac.T @ r / sigma_r**2 + w_prior * d_prior
        step = -np.linalg.solve(h, g)
        x += step
        if np.abs(step[:2]).max() < 1e-4 and abs(step[2]) < 1e-5:
            break
    return x, info


def fuse_with_prior(
    pose: np.ndarray, info: np.ndarray, prior: np.ndarray, prior_info: np.ndarray
) -> np.ndarray:
    """(3,) the pose that best agrees with both a match `pose` (3,) of information `info`
    (3, 3) and a `prior` (3,) of information `prior_info` (3, 3): the minimum of
    |x - pose|^2_info + |x - prior|^2_prior_info (headings compared on the circle), i.e.
    pose + (info + prior_info)^-1 prior_info (prior - pose). Along what the match fixes
    (info >> prior_info) it stays at the match; along what it leaves free (info ~ 0: a
    corridor's length, a featureless wall) it goes to the prior."""
    d = np.asarray(prior, dtype=np.float64) - pose
    d[2] = math.remainder(float(d[2]), 2.0 * math.pi)
    return pose + np.linalg.solve(info + prior_info, prior_info @ d)


def opposed_share(
    point_map: PointMap, points: np.ndarray, normals: np.ndarray, pose: np.ndarray, radius: float
) -> tuple[float, int]:
    """(share, pairs): of the scan points (M, 2) [robot frame] placed at `pose` (3,) that lie
    within `radius` [m] of a map point, the share whose normal faces the map point's the
    other way (cosine under -0.5). A scan's normals face the sensor that saw it
    (`point_normals`: the tangent in beam order turned left), so a scan matched onto the
    other face of a wall it never saw from that side (the occupancy score cannot tell the
    two faces apart) has nearly all its pairs opposed; a true match has nearly none. Points
    without a normal (isolated) are left out; (0.0, 0) without a map with normals."""
    tree, map_normals = point_map._tree, point_map._normals
    if tree is None or map_normals is None or len(points) == 0:
        return 0.0, 0
    has = np.hypot(normals[:, 0], normals[:, 1]) > 0.5
    xy, nrm = place(pose, points[has], normals[has])
    dist, idx = tree.query(xy, distance_upper_bound=radius)
    near = np.isfinite(dist)
    mn = map_normals[idx[near]]
    dots = (nrm[near] * mn).sum(axis=1)
    paired = np.hypot(mn[:, 0], mn[:, 1]) > 0.5
    n = int(paired.sum())
    return (float((dots[paired] < -0.5).mean()), n) if n else (0.0, 0)


def point_map_around(
    points: np.ndarray,
    normals: np.ndarray,
    centre: np.ndarray,
    reach: float,
    res: float,
    sigma: float,
    depth: int,
) -> PointMap:
    """The PointMap of map points (K, 2) [m] with their normals (K, 2), kept within `reach`
    [m] of `centre` (3,) in x and y (what a scan matched near there can reach) and cut to the
    points' extent (the grid need not cover empty space)."""
    bounds = (centre[0] - reach, centre[1] - reach, centre[0] + reach, centre[1] + reach)
    return PointMap(points, res, sigma, depth, _clip_bounds(points, bounds), normals)


def _clip_bounds(pts: np.ndarray, bounds: tuple[float, float, float, float]):
    """bounds cut to the points' extent."""
    if len(pts) == 0:
        return bounds
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    x0, y0 = max(bounds[0], lo[0]), max(bounds[1], lo[1])
    x1, y1 = min(bounds[2], hi[0]), min(bounds[3], hi[1])
    return (x0, y0, max(x0, x1), max(y0, y1))


def prior_chi2(pose: np.ndarray, prior: np.ndarray, sigma: tuple[float, float, float]) -> float:
    """chi^2 of `pose` (3,) against `prior` (3,) under independent `sigma` [m, m, rad]."""
    d = pose - prior
    d[2] = math.remainder(float(d[2]), 2.0 * math.pi)
    return float((np.square(d) / np.square(sigma)).sum())
