"""SlamParams: the GMapping settings (thesis values where the thesis set them), with units."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from worker.errors import InputError
from worker.slam.external.params import ExternalSlamParams
from worker.slam.graph.params import GraphSlamParams


@dataclass(frozen=True)
class SampledProposal:
    """rbpf's sampled improved proposal on a sparse step (Grisetti, Stachniss, Burgard 2007,
    Sec. IV, eqs. (9)-(11); worker.slam.proposal_kernels): each particle's pose is drawn from
    the Gaussian fitted to scan likelihood x motion model on a grid around its match, and its
    weight gets the Gaussian's normaliser, meant to keep the particles' spread where the scan
    does not fix the pose (along a corridor) instead of every copy of a parent on one match.

    The grid is GMapping's likelihood sampling (ROS llsamplerange, llsamplestep, lasamplerange,
    lasamplestep); its defaults (0.01, 0.01 m, 0.005, 0.005 rad) span one cell and cannot hold
    a spread: +-0.1 m covers 2.6 sigma of the motion model over a 1 m sparse step (srr 0.1 m/m
    over its 7 substeps: 0.038 m). Off by default, not a general gain on the three real logs
    (bench_reallogs, seeds 0 / 1 / 2, rbpf's final B error, off -> on): ACES 0.216 / 0.288 /
    0.274 -> 0.278 / 0.248 / 0.249 m, CSAIL 0.242 / 0.353 / 0.479 -> 0.279 / 0.228 / 0.254 m,
    Freiburg 079 0.199 / 0.216 / 0.205 -> 0.218 / 0.222 / 0.207 m, for 36-49 % more CPU. In a
    particle's own map the raw likelihood (beams independent, lsigma 0.075) varies by tens of
    log units between poses 0.1 m apart along a corridor, so the fitted Gaussian mostly sits
    on one grid pose, the match (docs/results/real-logs.md).
    """

    llsamplerange: float = 0.1  # [m] grid half-width in x and y (GMapping: 0.01)
    llsamplestep: float = 0.05  # [m] grid step in x and y, one cell (GMapping: 0.01)
    lasamplerange: float = 0.01  # [rad] grid half-width in theta (GMapping: 0.005)
    lasamplestep: float = 0.01  # [rad] grid step in theta (GMapping: 0.005)
    # times the grid may move to its fitted mean (whole steps, when that is half a step or
    # more off its centre): on a likelihood ridge the optimum the climb stopped at is one of
    # many, and the Gaussian belongs where the motion model puts its weight; 6 reach 0.6 m
    shifts: int = 6

    def __post_init__(self) -> None:
        for name in ("llsamplerange", "lasamplerange", "llsamplestep", "lasamplestep"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"SLAM parameter proposal.{name} must be >= 0, got {value}")
        if not (self.llsamplestep > 0 and self.lasamplestep > 0):
            raise InputError("SLAM parameters proposal.llsamplestep and lasamplestep must be > 0")
        if self.shifts < 0:
            raise InputError(f"SLAM parameter proposal.shifts must be >= 0, got {self.shifts}")


@dataclass(frozen=True)
class SlamParams:
    """Parameters of the SLAM algorithms, named after GMapping's ROS parameters.

    Defaults: the thesis settings (particles 40, angularUpdate 0.25, maxUrange 30) and
    GMapping's defaults elsewhere (slam_gmapping 1.x). The odometry baseline uses only the
    map and update-gating fields. JSON: `worker.param_io.to_dict` / `from_dict`.
    """

    particles: int = 40  # number of particles (thesis: 40; GMapping default 30)
    # update gating: the filter runs when any threshold is passed since the last update
    linear_update: float = 1.0  # [m] linearUpdate (0 = every scan)
    angular_update: float = 0.25  # [rad] angularUpdate (thesis; GMapping default 0.5)
    temporal_update: float = -1.0  # [s] temporalUpdate, negative = off
    resample_threshold: float = 0.5  # resample when Neff < this * particles
    # map
    delta: float = 0.05  # [m] map resolution
    max_urange: float = 30.0  # [m] maxUrange: beams are cut to this length (thesis: 30)
    max_range: float | None = None  # [m] maxRange: longer beams ignored; None = laser max - 0.01
    occ_thresh: float = 0.25  # occupied above this hit/visit ratio when published (ROS map)
    map_margin: float = 8.0  # [m] growth margin when a scan leaves the allocated map area
    # scan matcher (improved proposal)
    sigma: float = 0.05  # [m] sigma of the matching score (GMapping: exp(-mu^2 / sigma))
    kernel_size: int = 1  # [cells] search window around each beam end point (at most 15)
    lstep: float = 0.05  # [m] initial translational step of the hill climbing
    astep: float = 0.05  # [rad] initial angular step of the hill climbing
    iterations: int = 5  # step halvings of the hill climbing
    lsigma: float = 0.075  # [m^2] beam log-likelihood is -mu^2 / lsigma (weights)
    ogain: float = 3.0  # gain smoothing the likelihood when normalising weights
    lskip: int = 0  # beams skipped between two used ones when matching
    # coarse to fine (a departure from GMapping, off at 0): the hill climbing's first
    # coarse_levels step sizes use every (coarse_skip + 1)-th used beam, the rest all of them;
    # the final pose, score and likelihood are all-beam ones (match_kernels.optimize). Off by
    # default: 1 / 3 ran 1.14x faster on one core but made the A errors of 30 closed-loop runs
    # 5 % worse, significantly (docs/results/speed.md,
    # "Coarse-to-fine scan matching")
    coarse_skip: int = 0
    coarse_levels: int = 0
    minimum_score: float = 0.0  # below this match score, keep the odometry guess
    # scan-matching threads (numba prange over particles); results do not depend on it. At 1
    # (the default) a run executed alone takes its process's share of the cores instead
    # (worker.slam.threads: `mapqual run` and `mapqual worker --concurrency 1` use them all, a
    # batch's pool one each); the summary records the number used.
    threads: int = 1
    # motion model (GMapping's MotionModel::drawFromMotion)
    srr: float = 0.1  # [m/m] translation noise from translation
    srt: float = 0.2  # [rad/m] rotation noise from translation
    str_: float = 0.1  # [m/rad] translation noise from rotation (GMapping's `str`)
    stt: float = 0.2  # [rad/rad] rotation noise from rotation
    # graph SLAM's own settings; None = its defaults, and no key in the stored JSON (so rbpf
    # runs keep their JSON and run keys); a graph run stores them (`with_defaults_for`)
    graph: GraphSlamParams | None = field(default=None, metadata={"omit_if_none": True})
    # the program an "external" run drives over the protocol; None (and no key) otherwise
    external: ExternalSlamParams | None = field(default=None, metadata={"omit_if_none": True})
    # a scan step longer than this (a log that kept one scan a metre) has its noise drawn as
    # the sum over the robot-sized steps it stands for (worker.slam.motion.draw_from_motion);
    # no step of a 10 Hz log under 1.5 m/s and 1.5 rad/s reaches it. 0 = off (one draw, as
    # GMapping); such a scan is always an update, the matcher also climbs from the noise-free
    # prediction and from a wide climb (rbpf.WideSearch), and the odometry's per-axis scale
    # is learnt and applied to such steps (worker.slam.odomcal); docs/results/real-logs.md
    motion_substep: float = 0.15  # [m]
    motion_substep_angle: float = 0.15  # [rad]
    # on such a sparse step, the sampled improved proposal (SampledProposal); None = off (the
    # default: it did not help on the real logs, see SampledProposal), and no key in the JSON
    proposal: SampledProposal | None = field(default=None, metadata={"omit_if_none": True})

    def __post_init__(self) -> None:
        positive = ("delta", "max_urange", "sigma", "lstep", "astep", "lsigma", "ogain")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"SLAM parameter {name} must be a positive number, got {value}")
        nonneg = (
            "linear_update",
            "angular_update",
            "srr",
            "srt",
            "str_",
            "stt",
            "map_margin",
            "motion_substep",
            "motion_substep_angle",
        )
        for name in nonneg:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"SLAM parameter {name} must be >= 0, got {value}")
        if self.particles < 1:
            raise InputError(f"SLAM parameter particles must be >= 1, got {self.particles}")
        if self.threads < 1:
            raise InputError(f"SLAM parameter threads must be >= 1, got {self.threads}")
        if self.kernel_size < 0 or self.iterations < 0 or self.lskip < 0:
            raise InputError("SLAM parameters kernel_size, iterations and lskip must be >= 0")
        if self.coarse_skip < 0 or not 0 <= self.coarse_levels <= self.iterations:
            raise InputError(
                "SLAM parameters coarse_skip must be >= 0 and coarse_levels in [0, iterations "
                f"= {self.iterations}], got {self.coarse_skip} and {self.coarse_levels}"
            )
        if self.kernel_size > 15:
            raise InputError(f"SLAM parameter kernel_size must be <= 15, got {self.kernel_size}")
        if not 0.0 <= self.resample_threshold <= 1.0:
            raise InputError(
                "SLAM parameter resample_threshold must be in [0, 1], "
                f"got {self.resample_threshold}"
            )
        if not 0.0 < self.occ_thresh < 1.0:
            raise InputError(f"SLAM parameter occ_thresh must be in (0, 1), got {self.occ_thresh}")
        if self.max_range is not None and not (self.max_range > 0):
            raise InputError(f"SLAM parameter max_range must be positive, got {self.max_range}")


def with_defaults_for(params: SlamParams, algorithm: str) -> SlamParams:
    """params with the graph settings filled in when the algorithm is graph SLAM, so that they
    are stored with the run. slam.external belongs to "external" runs: refused when one has
    none, dropped (not stored) for the other algorithms, so that one --params file serves a
    batch that compares `--slam rbpf,external`."""
    if algorithm == "external" and params.external is None:
        raise InputError("algorithm 'external' needs slam.external {name, command}")
    if algorithm != "external" and params.external is not None:
        params = replace(params, external=None)
    if algorithm == "graph" and params.graph is None:
        return replace(params, graph=GraphSlamParams())
    return params
