"""GMapping-class Rao-Blackwellized particle filter (Grisetti, Stachniss, Burgard 2007)."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from worker.evaluate.se2 import compose, inverse
from worker.slam.base import LaserGeometry, beam_angles, beam_limits
from worker.slam.gating import UpdateGate, check_scan
from worker.slam.grid import OccupancyGrid
from worker.slam.keyposes import Lineage, relative_many
from worker.slam.match_all_kernels import scan_match_all, scan_match_all_parallel
from worker.slam.match_kernels import (
    C_ASTEP,
    C_COARSE_LEVELS,
    C_ITERATIONS,
    C_KERNEL,
    C_LSKIP,
    C_LSTEP,
    match_config,
)
from worker.slam.motion import (
    compose3,
    draw_from_motion,
    motion_std,
    motion_substeps,
    relative3,
)
from worker.slam.odomcal import ScaleEstimate
from worker.slam.params import SampledProposal, SlamParams
from worker.slam.patchmap import PatchMaps
from worker.slam.proposal_kernels import fit_proposals, fit_proposals_parallel, sample_offsets
from worker.slam.resample import normalized_weights, systematic_indices


@dataclass(frozen=True)
class WideSearch:
    """The coarse climb tried after a sparse step (one longer than motion_substep), before the
    fine one: a wider window around each beam end point, longer first steps."""

    kernel_size: int = 3  # [cells] window half-width (0.15 m at 0.05 m cells; fine: 1)
    lstep: float = 0.1  # [m] initial translational step (fine: lstep)
    astep: float = 0.1  # [rad] initial angular step (fine: astep)
    iterations: int = 3  # step halvings
    lskip: int = 1  # beams skipped between two used ones


class RbpfSlam:
    """Particles = (pose, map); the map frame is the odometry frame of the first scan.

    Every scan moves the particles by the odometry step through the motion model. An update
    (update gating as GMapping) then refines each particle by scan matching against its own
    map (the improved proposal), adds the match log-likelihood to its weight, resamples when
    Neff < resample_threshold * N, and registers the scan in every particle's map. The
    estimate is the best particle's (largest summed log-likelihood, as slam_gmapping) map->odom
    correction at the last update, composed with the current odometry.
    """

    name = "rbpf"

    def __init__(self, laser: LaserGeometry, params: SlamParams, rng: np.random.Generator):
        self.params = params
        self.rng = rng
        angles = beam_angles(laser)
        self._n_beams = angles.shape[0]
        self._cos_a, self._sin_a = np.cos(angles), np.sin(angles)
        self._max_range, self._usable = beam_limits(laser, params)
        self._match_cfg = match_config(
            res=params.delta,
            usable_range=self._usable,
            max_range=self._max_range,
            lskip=params.lskip,
            kernel=params.kernel_size,
            sigma=params.sigma,
            lsigma=params.lsigma,
            lstep=params.lstep,
            astep=params.astep,
            iterations=params.iterations,
            minimum_score=params.minimum_score,
            coarse_skip=params.coarse_skip,
            coarse_levels=params.coarse_levels,
        )
        wide = WideSearch()
        self._wide_cfg = self._match_cfg.copy()
        for key, value in (
            (C_KERNEL, wide.kernel_size),
            (C_LSTEP, wide.lstep),
            (C_ASTEP, wide.astep),
            (C_ITERATIONS, wide.iterations),
            (C_LSKIP, max(wide.lskip, params.lskip)),
            (C_COARSE_LEVELS, 0),  # it skips beams already
        ):
            self._wide_cfg[key] = value
        prop = params.proposal
        if prop is not None:
            self._offsets = sample_offsets(
                prop.llsamplerange, prop.llsamplestep, prop.lasamplerange, prop.lasamplestep
            )
            self._steps = np.array([prop.llsamplestep, prop.llsamplestep, prop.lasamplestep])
        self._gate = UpdateGate(params.linear_update, params.angular_update, params.temporal_update)
        n = params.particles
        self.maps = PatchMaps(n, params.delta, params.map_margin, params.occ_thresh)
        self.poses = np.zeros((n, 3))  # (N, 3) [x, y, theta] map frame
        self.log_weights = np.zeros(n)  # since the last resampling (GMapping's weight)
        self.log_weight_sums = np.zeros(n)  # over the whole run (GMapping's weightSum)
        self.neff = float(n)
        self.updates = 0
        self.resamplings = 0
        self._odom_last: np.ndarray | None = None
        self._pose_odom = np.zeros(3)
        self._T_map_odom = np.zeros(3)
        self._best = 0
        self._grid: OccupancyGrid | None = None  # cached map of the latest update
        self._pred: np.ndarray | None = None  # (N, 3) noise-free predictions since the update
        self._sparse = False  # a sparse step since the last update
        self._raw_last = np.zeros(3)  # the raw odometry of the previous scan
        self._at_update = (np.zeros(3), self.poses.copy())  # raw odometry, poses at the update
        self._scale = ScaleEstimate()  # the odometry's learnt scale (sparse steps only)
        self.lineage = Lineage()  # every particle's path, for the final trajectory

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        ranges = self.advance(t, pose_odom, ranges_m)
        return ranges is not None and self.update(ranges)

    def advance(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray):
        """`process`'s cheap first half: move the particles to this scan, and gate. The scan's
        ranges when it is an update (then `update(ranges)` makes it), else None. (The real-time
        wrapper runs the two halves apart: worker.slam.realtime.)"""
        t, raw, ranges = check_scan(t, pose_odom, ranges_m, self._n_beams)
        p = self.params
        self.lineage.scan(raw)
        if self._odom_last is None:
            pose = raw
            self.poses[:] = pose  # the map frame starts at the first odometry pose
        else:
            pose = self._calibrated(raw)
            self._predict(pose)
            self.poses = draw_from_motion(
                self.poses,
                pose,
                self._odom_last,
                p.srr,
                p.srt,
                p.str_,
                p.stt,
                self.rng,
                (p.motion_substep, p.motion_substep_angle),
            )
        self._odom_last = pose
        self._raw_last = raw
        self._pose_odom = raw
        if not self._gate.step(t, pose, self._sparse):
            return None
        return ranges

    def update(self, ranges: np.ndarray) -> bool:
        """`process`'s second half on a scan `advance` gated through: match, weigh, resample,
        register (True)."""
        raw = self._raw_last
        if self.updates > 0:
            self._proposal_and_weights(ranges, self._pred if self._sparse else None)
            if self._sparse:
                self._learn_scale(raw)
            same_as, parents = self._maybe_resample()
        else:  # the first scan: every particle at the same pose, with the same empty map
            same_as, parents = np.zeros(self.poses.shape[0], dtype=np.int64), None
        self.lineage.update(self.poses, parents)
        self.maps.register(
            self.poses, ranges, self._cos_a, self._sin_a, self._usable, self._max_range, same_as,
            parallel=self._parallel(),
        )  # fmt: skip
        self.updates += 1
        self._pred = None
        self._sparse = False
        self._grid = None
        self._best = int(np.argmax(self.log_weight_sums))
        self._T_map_odom = compose(self.poses[self._best], inverse(raw))
        self._at_update = (raw, self.poses.copy())
        return True

    def _calibrated(self, raw: np.ndarray) -> np.ndarray:
        """The odometry pose the filter moves by: the raw step since the last scan, scaled per
        axis by the learnt scale when it is a sparse step (see worker.slam.odomcal)."""
        step = relative3(self._raw_last, raw)
        p = self.params
        substep = (p.motion_substep, p.motion_substep_angle)
        if motion_substeps(float(np.hypot(*step[:2])), abs(float(step[2])), substep) > 1:
            step = step * self._scale.scale
        elif np.array_equal(self._odom_last, self._raw_last):
            return raw  # no sparse step yet (a 10 Hz log): the raw odometry, bit for bit
        return compose3(self._odom_last, step)

    def _learn_scale(self, raw: np.ndarray) -> None:
        """Add the raw odometry step since the last update and the particles' weighted mean
        matched step (before resampling: the rows still match those of the last update)."""
        raw_then, poses_then = self._at_update
        weights, _ = normalized_weights(self.log_weights, self.params.ogain)
        matched = relative_many(poses_then, self.poses)
        self._scale.add(relative3(raw_then, raw), weights @ matched)

    def _predict(self, pose: np.ndarray) -> None:
        """Note a sparse step (one the motion model draws as several, see draw_from_motion),
        and carry each particle's noise-free prediction since the last update."""
        p = self.params
        step = relative3(self._odom_last, pose)
        substep = (p.motion_substep, p.motion_substep_angle)
        if self._pred is None:
            self._pred = self.poses.copy()
        self._pred = _compose_all(self._pred, step)
        self._sparse = (
            self._sparse
            or motion_substeps(float(np.hypot(*step[:2])), abs(float(step[2])), substep) > 1
        )

    def _parallel(self) -> bool:
        """Whether the particles are matched and registered on numba's threads (slam.threads
        > 1; then that many, at most numba's)."""
        if self.params.threads <= 1:
            return False
        numba.set_num_threads(min(self.params.threads, numba.config.NUMBA_NUM_THREADS))
        return True

    def _proposal_and_weights(self, ranges: np.ndarray, pred: np.ndarray | None) -> None:
        """The improved proposal; after a sparse step (a log that kept one scan a metre) each
        particle's fine climb is also started from its noise-free odometry prediction and from
        the end of a wide climb (WideSearch), and the best-scoring of the three results is
        kept: a wider search where the odometry moved more than a robot's step between two
        scans. Then, with params.proposal, each particle's pose is drawn from the Gaussian
        fitted around that optimum (`_sampled`)."""
        m = self.maps
        parallel = self._parallel()
        match = scan_match_all_parallel if parallel else scan_match_all
        args = (ranges, self._cos_a, self._sin_a, self._match_cfg)
        maps = (m.mean, m.bits, m.match_tables(), m.tpx0, m.tpy0)
        poses, scores, likes = match(*maps, self.poses, *args)
        if pred is not None:
            coarse, _, _ = match(*maps, self.poses, *args[:-1], self._wide_cfg)
            for start in (pred, coarse):
                alt, alt_scores, alt_likes = match(*maps, start, *args)
                better = alt_scores > scores
                poses[better] = alt[better]
                scores = np.where(better, alt_scores, scores)
                likes = np.where(better, alt_likes, likes)
            if self.params.proposal is not None:
                poses, likes = self._sampled(ranges, poses, pred, parallel, self.params.proposal)
        self.poses = poses
        self.log_weights += likes
        self.log_weight_sums += likes

    def _sampled(
        self,
        ranges: np.ndarray,
        modes: np.ndarray,
        pred: np.ndarray,
        parallel: bool,
        prop: SampledProposal,
    ) -> tuple[np.ndarray, np.ndarray]:
        """(poses (N, 3), log weight factors (N,)): each particle's pose drawn from the Gaussian
        of scan likelihood x motion model fitted on the sampling grid around its optimum
        `modes`, and the log of its normaliser (Grisetti et al. 2007, eqs. (9)-(11)). Keeping
        the optimum alone puts every copy of a parent at one place along a featureless
        corridor, where only the odometry knows the distance (docs/results/real-logs.md); the
        draw is meant to keep the motion model's spread there and the match's precision across
        (what it did on the real logs: SampledProposal)."""
        m = self.maps
        fit = fit_proposals_parallel if parallel else fit_proposals
        mus, covs, log_eta = fit(
            m.mean, m.bits, m.match_tables(), m.tpx0, m.tpy0, modes, pred,
            self._prior_information(pred), ranges, self._cos_a, self._sin_a, self._offsets,
            self._steps, prop.shifts, self._match_cfg,
        )  # fmt: skip
        return draw_gaussians(mus, covs, self.rng), log_eta

    def _prior_information(self, pred: np.ndarray) -> np.ndarray:
        """(N, 3, 3) the inverse covariance, map frame, of each particle's motion model since
        the last update: draw_from_motion's deviations for the whole (calibrated) odometry step
        as one step of its k substeps (exact for the one step a sparse log makes between two
        updates; for a dense stretch ended by a sparse step, its k robot-sized steps' noise as
        the sum of the dense steps' would be), rotated by the particle's heading then."""
        p = self.params
        poses_then = self._at_update[1]
        step = relative3(poses_then[0], pred[0])  # the same odometry step for every particle
        std = motion_std(
            step, p.srr, p.srt, p.str_, p.stt, (p.motion_substep, p.motion_substep_angle)
        )
        vx, vy, vt = np.maximum(std * std, _MIN_PRIOR_VAR)
        c, s = np.cos(poses_then[:, 2]), np.sin(poses_then[:, 2])
        # inv(R diag(vx, vy) R^T) = R diag(1/vx, 1/vy) R^T
        info = np.zeros((poses_then.shape[0], 3, 3))
        info[:, 0, 0] = c * c / vx + s * s / vy
        info[:, 1, 1] = s * s / vx + c * c / vy
        info[:, 0, 1] = info[:, 1, 0] = c * s * (1.0 / vx - 1.0 / vy)
        info[:, 2, 2] = 1.0 / vt
        return info

    def _maybe_resample(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Resample when Neff is low. Returns (None, None), or after resampling which particle
        each one is a copy of (same_as for PatchMaps.register: the first copy of its parent)
        and the index of its parent before."""
        weights, self.neff = normalized_weights(self.log_weights, self.params.ogain)
        n = self.poses.shape[0]
        if self.neff >= self.params.resample_threshold * n:
            return None, None
        idx = systematic_indices(weights, self.rng)  # sorted: copies of a parent are adjacent
        self.poses = self.poses[idx]
        self.log_weight_sums = self.log_weight_sums[idx]
        self.log_weights = np.zeros(n)
        self.maps.select(idx)
        self.resamplings += 1
        return np.searchsorted(idx, idx, side="left"), idx

    def pose_estimate(self) -> np.ndarray:
        return compose3(self._T_map_odom, self._pose_odom)

    def final_trajectory(self) -> np.ndarray:
        """(N, 3) the pose at every scan processed so far along the best particle's path (its
        pose at each update, as GMapping's trajectory tree keeps it, with the odometry between
        updates blended as in worker.slam.keyposes.between_keys): offline SLAM's answer, the
        path the final map was built along. pose_estimate gave the online one, the best
        particle of each moment, which resampling may since have dropped."""
        return self.lineage.trajectory(self._best)

    def T_map_odom(self) -> np.ndarray:
        return self._T_map_odom.copy()

    def occupancy(self) -> OccupancyGrid:
        # the grid is immutable: rebuild it only after an update changed the maps
        if self._grid is None:
            self._grid = self.maps.occupancy(self._best)
        return self._grid

    def occupancy_with_hits(self) -> OccupancyGrid:
        """`occupancy` with its cells' end-point counts (for the map score; not cached)."""
        return self.maps.occupancy(self._best, with_hits=True)

    def map_changes(self) -> np.ndarray:
        """(K, 4) [x0, y0, x1, y1] map frame [m]: rectangles covering every cell in which the
        map `occupancy` gives now differs from the one it gave at the previous call of
        map_changes (the first call: every seen cell); (0, 4) when none does. What the scans
        since then wrote, and where the best particle changed: a map consumer (the costmap)
        refreshes these only. Rectangles are whole 32-cell patches and do not overlap."""
        return self.maps.changes(self._best)


# [m^2 or rad^2] the smallest motion-model variance of the proposal's prior: a noise-free model
# (srr = ... = 0, as some tests set) pins the draw to the odometry instead of dividing by zero
_MIN_PRIOR_VAR = 1e-12


def draw_gaussians(mus: np.ndarray, covs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 3) one draw from each N(mus[i] (3,), covs[i] (3, 3)): mu + A z with A A^T = Sigma
    from the eigen-decomposition (a fitted covariance may be singular: all the weight on one
    grid pose gives Sigma = 0, the optimum itself); one (N, 3) standard normal draw."""
    lam, vec = np.linalg.eigh(covs)
    a = vec * np.sqrt(np.clip(lam, 0.0, None))[:, None, :]
    z = rng.standard_normal(mus.shape)
    out = mus + np.einsum("nij,nj->ni", a, z)
    out[:, 2] = (out[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return out


def _compose_all(poses: np.ndarray, step: np.ndarray) -> np.ndarray:
    """(N, 3) each pose (+) the same step (3,)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    th = poses[:, 2] + step[2]
    return np.column_stack(
        [
            poses[:, 0] + c * step[0] - s * step[1],
            poses[:, 1] + s * step[0] + c * step[1],
            (th + np.pi) % (2 * np.pi) - np.pi,
        ]
    )
