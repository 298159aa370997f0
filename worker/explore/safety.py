"""Safety controller (range_proximity_safety_controller): back off, turn away from obstacles."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

from worker.explore.params import CostmapParams, DwaParams, SafetyParams


def median_ranges(ranges_m: np.ndarray, beams: int) -> np.ndarray:
    """Each reading replaced by the median of `beams` neighbours (laser_filters' median
    filter; the ends repeat their last reading); 1: the readings as they are."""
    if beams <= 1:
        return ranges_m
    return ndimage.median_filter(np.asarray(ranges_m), size=beams, mode="nearest")


def front_clearance(
    ranges_m: np.ndarray,
    angles: np.ndarray,
    range_max: float,
    half: float,
    lateral: float,
    slack: float = 0.0,
    min_points: int = 1,
) -> tuple[float, float]:
    """Distance [m] from the footprint's front edge to the nearest scan hit in the robot's way.

    The laser sits at the robot's centre; a hit at (x, y) in the robot frame is in the way
    when x > half and |y| < half + lateral (the band the robot sweeps driving straight on):
    a door jamb beside the robot is not. With `slack` > 0 a hit must also stay in the band
    moved `slack` farther along its own beam (where it would be had the reading come out
    that much short): a wall beside the robot read obliquely and short lands in the band,
    the same reading at its likely place does not; a hit straight ahead barely moves
    sideways, so the distance ahead is unchanged. With `min_points` > 1 the distance is the
    min_points-th nearest hit in the way (nav2 collision monitor's `min_points`). The
    controller uses neither: both are alternatives `benchmarks/bench_safety.py` scores, and
    both let real obstacles pass on a noisy laser (docs/results/laser-noise.md). Returns (inf, 0)
    when nothing is in the way; side is +1 for an obstacle on the left (y > 0), -1 on the
    right.
    """
    hit = ranges_m < range_max * 0.999
    if not hit.any():
        return math.inf, 0.0
    r = ranges_m[hit]
    a = angles[hit]
    s = np.sin(a)
    x = r * np.cos(a)
    y = r * s
    band = half + lateral
    ahead = (x > half) & (np.abs(y) < band)
    if slack > 0.0:
        ahead &= np.abs((r + slack) * s) < band
    n = int(np.count_nonzero(ahead))
    if n < min_points:
        return math.inf, 0.0
    d = x[ahead] - half
    k = (
        int(np.argpartition(d, min_points - 1)[min_points - 1])
        if min_points > 1
        else int(np.argmin(d))
    )
    return float(d[k]), (1.0 if y[ahead][k] > 0 else -1.0)


class SafetyController:
    """Overrides the planner for a short manoeuvre when an obstacle is too close in front."""

    def __init__(
        self,
        params: SafetyParams,
        costmap: CostmapParams,
        dwa: DwaParams,
        angles: np.ndarray,
        range_max: float,
        median: int = 1,
    ):
        """costmap: the footprint's settings; dwa: its escape_vel is the back-off speed;
        median: each beam read as the median of this many neighbours (1: raw)."""
        self.params = params
        self.half_m = costmap.footprint_half_m  # [m]
        self.padding_m = costmap.footprint_padding  # [m]
        self.escape_vel = dwa.escape_vel  # [m/s]
        self.angles = angles
        self.range_max = range_max
        self.median = int(median)
        self._until = -math.inf
        self._turn = 0.0
        self.n_triggers = 0

    def active(self, t: float) -> bool:
        return t < self._until

    def check(self, t: float, ranges_m: np.ndarray, v_cmd: float) -> tuple[float, float] | None:
        """The override (v, w) for this period, or None to let the planner drive.

        Triggers only while moving forwards (v_cmd > 0) with a hit closer than safety_distance
        to the footprint's front, in its way (the readings median-filtered over `median`
        beams first): backs off at escape_vel, turning away from the obstacle's side.
        """
        p = self.params
        if t < self._until:
            return (self.escape_vel, self._turn)
        if v_cmd <= 0.0:
            return None
        ranges_m = median_ranges(ranges_m, self.median)
        d, side = front_clearance(
            ranges_m, self.angles, self.range_max, self.half_m, self.padding_m
        )
        if d >= p.safety_distance:
            return None
        self.n_triggers += 1
        self._until = t + p.safety_backoff_time
        # Obstacle on the left (side +1): turn clockwise so that the nose points away from it.
        self._turn = -side * p.safety_turn_vel
        return (self.escape_vel, self._turn)
