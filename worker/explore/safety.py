"""Safety controller (range_proximity_safety_controller): back off, turn away from obstacles."""

from __future__ import annotations

import math

import numpy as np

from worker.explore.params import ExploreParams


def in_the_way(
    ranges_m: np.ndarray, angles: np.ndarray, range_max: float, half: float, lateral: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per beam: the distance [m] from the footprint's front edge to its hit when the hit is
    in the robot's way (inf otherwise), and the hit's side (+1 left, y > 0; -1 right).

    The laser sits at the robot's centre; a hit at (x, y) in the robot frame is in the way
    when x > half and |y| < half + lateral (the band the robot sweeps driving straight on):
    a door jamb beside the robot is not. Readings at range_max are no hits.
    """
    r = np.asarray(ranges_m, dtype=float)
    x = r * np.cos(angles)
    y = r * np.sin(angles)
    ahead = (r < range_max * 0.999) & (x > half) & (np.abs(y) < half + lateral)
    return np.where(ahead, x - half, np.inf), np.where(y > 0, 1.0, -1.0)


def front_clearance(
    ranges_m: np.ndarray, angles: np.ndarray, range_max: float, half: float, lateral: float
) -> tuple[float, float]:
    """Distance [m] from the footprint's front edge to the nearest scan hit in the robot's way
    (`in_the_way`), and its side; (inf, 0) when nothing is in the way."""
    d, side = in_the_way(ranges_m, angles, range_max, half, lateral)
    k = int(np.argmin(d))
    if not np.isfinite(d[k]):
        return math.inf, 0.0
    return float(d[k]), float(side[k])


class SafetyController:
    """Overrides the planner for a short manoeuvre when an obstacle is too close in front.

    An obstacle counts when two consecutive scans (`see`, every control period) put a hit
    in the way nearer than safety_distance on the same beam or its neighbour: a real
    obstacle is there in both, a noisy short reading (laser noise) on one beam is not,
    which at 0.1 m of noise made the robot back off at every door jamb. At full speed the
    second scan comes 0.085 m later.
    """

    def __init__(self, params: ExploreParams, angles: np.ndarray, range_max: float):
        self.params = params
        self.angles = angles
        self.range_max = range_max
        self._until = -math.inf
        self._turn = 0.0
        self.n_triggers = 0
        self._close = np.zeros(len(angles), dtype=bool)  # the latest scan's close beams
        self._before = np.zeros(len(angles), dtype=bool)  # the scan before's
        self._dist = np.full(len(angles), np.inf)
        self._side = np.zeros(len(angles))
        self._seen_t = -math.inf

    def active(self, t: float) -> bool:
        return t < self._until

    def see(self, t: float, ranges_m: np.ndarray) -> None:
        """Take this control period's scan."""
        p = self.params
        d, side = in_the_way(
            ranges_m, self.angles, self.range_max, p.footprint_half_m, p.footprint_padding
        )
        gap = t - self._seen_t
        self._seen_t = t
        self._before = (
            self._close if gap <= 1.5 / p.controller_frequency else np.zeros_like(self._close)
        )
        self._dist, self._side = d, side
        self._close = d < p.safety_distance

    def check(self, t: float, ranges_m: np.ndarray, v_cmd: float) -> tuple[float, float] | None:
        """The override (v, w) for this period, or None to let the planner drive.

        Triggers only while moving forwards (v_cmd > 0) with a hit closer than safety_distance
        to the footprint's front, in its way, in this scan and the one before (`see`; a
        scan not yet seen is taken now): backs off at escape_vel, turning away from the
        obstacle's side.
        """
        p = self.params
        if t < self._until:
            return (p.escape_vel, self._turn)
        if v_cmd <= 0.0:
            return None
        if t != self._seen_t:
            self.see(t, ranges_m)
        b = self._before
        confirmed = self._close & (b | np.roll(b, 1) | np.roll(b, -1))
        if not confirmed.any():
            return None
        k = int(np.argmin(np.where(confirmed, self._dist, np.inf)))
        self.n_triggers += 1
        self._until = t + p.safety_backoff_time
        # Obstacle on the left (side +1): turn clockwise so that the nose points away from it.
        self._turn = -self._side[k] * p.safety_turn_vel
        return (p.escape_vel, self._turn)
