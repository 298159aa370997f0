"""Stage-like 2D simulator: differential drive with limits, collisions, laser, odometry."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from worker.errors import InputError
from worker.evaluate.se2_scalar import wrap_fold
from worker.sim import odometry
from worker.sim.collision import advance, footprint_collides
from worker.sim.params import SimParams
from worker.world.analysis import clearance_map
from worker.world.raycast import cast_scan_skip, jump_map
from worker.world.world import World


@dataclass(frozen=True)
class Collision:
    """The robot was blocked by an obstacle at time `t` [s], pose [x, y, theta] (last free)."""

    t: float
    x: float
    y: float
    theta: float


def add_range_noise(
    ranges: np.ndarray, sigma: float, range_max: float, rng: np.random.Generator
) -> np.ndarray:
    """`ranges (B,)` with Gaussian range noise of `sigma` [m] on the beams that hit something
    (one normal draw per beam, hit or not), clipped to [0, range_max]; beams reading
    range_max (no return) keep it."""
    hit = ranges < range_max
    noisy = ranges + sigma * rng.standard_normal(ranges.shape[0])
    return np.where(hit, np.clip(noisy, 0.0, range_max), ranges)


class Simulator:
    """Steps a differential-drive robot through a World in simulated time.

    `pose_gt` and `pose_odom` are `(3,)` [x, y, theta]; the odometry frame coincides with the
    world frame at t = 0. A collision stops the robot (velocities zeroed) and is recorded once
    per contact; the robot may drive away from the obstacle afterwards.
    """

    def __init__(
        self,
        world: World,
        params: SimParams | None = None,
        rng: np.random.Generator | None = None,
        start_pose=None,
    ):
        self.world = world
        self.params = params or SimParams()
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._occ = world.occ
        self._res = float(world.resolution)
        self._ox = float(world.origin[0])
        self._oy = float(world.origin[1])
        self._half = 0.5 * self.params.footprint
        self._angles = self.params.laser.angles
        clearance = world.clearance
        if clearance is None:  # a World built by hand rather than by World.from_array
            clearance = clearance_map(world.occ, self._res)
        self._jump = jump_map(world.occ, clearance, self._res)
        pose = np.asarray(world.start_pose if start_pose is None else start_pose, dtype=float)
        self._x, self._y, self._th = float(pose[0]), float(pose[1]), wrap_fold(pose[2])
        if self._collides(self._x, self._y, self._th):
            raise InputError(
                f"{world.name}: the robot's {self.params.footprint:.2f} m footprint at the start "
                f"pose ({self._x:.2f}, {self._y:.2f}) overlaps an obstacle"
            )
        self._ox_odom, self._oy_odom, self._oth_odom = self._x, self._y, self._th
        self._v = 0.0  # [m/s] actual velocities
        self._w = 0.0  # [rad/s]
        self._steps = 0
        self._in_contact = False
        self.collisions: list[Collision] = []
        p = self.params
        if p.odom_model == "stage":
            # Stage: one error factor per axis per run, uniform in [-E/2, E/2].
            e = np.asarray(p.odom_error, dtype=float)
            self.odom_error_factors = self.rng.uniform(-0.5 * e, 0.5 * e)
        else:
            self.odom_error_factors = np.zeros(3)

    def _collides(self, x: float, y: float, th: float) -> bool:
        return bool(
            footprint_collides(self._occ, self._res, self._ox, self._oy, x, y, th, self._half)
        )

    @property
    def t(self) -> float:
        """Simulated time [s] (an integer number of steps times dt, no drift)."""
        return self._steps * self.params.dt

    @property
    def pose_gt(self) -> np.ndarray:
        """True pose `(3,)` [x, y, theta] in the world frame."""
        return np.array([self._x, self._y, self._th])

    @property
    def pose_odom(self) -> np.ndarray:
        """Odometry pose `(3,)` [x, y, theta] in the odom frame."""
        return np.array([self._ox_odom, self._oy_odom, self._oth_odom])

    @property
    def velocity(self) -> tuple[float, float]:
        """Actual (v [m/s], w [rad/s])."""
        return self._v, self._w

    @property
    def collided(self) -> bool:
        """Whether any collision happened so far."""
        return bool(self.collisions)

    @property
    def in_contact(self) -> bool:
        """Whether the robot is in a contact: blocked, and not yet a cell clear of the obstacle."""
        return self._in_contact

    def step(self, v_cmd: float, w_cmd: float) -> bool:
        """Advance one dt towards the commanded velocities; returns False if blocked."""
        p = self.params
        dt = p.dt
        if not (math.isfinite(v_cmd) and math.isfinite(w_cmd)):
            raise ValueError(f"velocity command must be finite, got ({v_cmd}, {w_cmd})")
        v_target = min(max(float(v_cmd), p.v_min), p.v_max)
        w_target = min(max(float(w_cmd), -p.w_max), p.w_max)
        dv = p.acc_lin * dt
        dw = p.acc_ang * dt
        v = self._v + min(max(v_target - self._v, -dv), dv)
        w = self._w + min(max(w_target - self._w, -dw), dw)
        x0, y0, th0 = self._x, self._y, self._th
        x, y, th, blocked, t_hit = advance(
            self._occ, self._res, self._ox, self._oy, x0, y0, th0, v, w, dt, self._half
        )
        self._x, self._y, self._th = float(x), float(y), wrap_fold(float(th))
        if blocked:
            self._v = 0.0
            self._w = 0.0
            if not self._in_contact:
                self.collisions.append(Collision(self.t + t_hit, self._x, self._y, self._th))
            self._in_contact = True
        else:
            self._v, self._w = v, w
            # A contact lasts until the robot is clear of the obstacle by a cell, so pushing
            # against a wall is one collision, not one per step.
            if self._in_contact:
                self._in_contact = bool(
                    footprint_collides(
                        self._occ,
                        self._res,
                        self._ox,
                        self._oy,
                        self._x,
                        self._y,
                        self._th,
                        self._half + self._res,
                    )
                )
        self._update_odometry(x0, y0, th0)
        self._steps += 1
        return not blocked

    def _update_odometry(self, x0: float, y0: float, th0: float) -> None:
        """Apply the true increment of this step, corrupted by the odometry model."""
        d = odometry.relative_motion(x0, y0, th0, self._x, self._y, self._th)
        if self.params.odom_model == "stage":
            d = odometry.stage_increment(d, self.odom_error_factors)
        else:
            d = odometry.gaussian_increment(d, self.params.odom_sigmas, self.rng)
        self._ox_odom, self._oy_odom, self._oth_odom = odometry.compose(
            self._ox_odom, self._oy_odom, self._oth_odom, *d
        )

    def scan(self) -> np.ndarray:
        """Laser ranges `(B,)` float64 [m] at the true pose, with the configured range noise.

        Beams that hit nothing read exactly `range_max`; noisy readings are clipped to
        [0, range_max].
        """
        ranges = self.scan_noise_free()
        sigma = self.params.laser_noise_sigma
        if sigma > 0.0:
            ranges = add_range_noise(ranges, sigma, self.params.laser.range_max, self.rng)
        return ranges

    def scan_noise_free(self) -> np.ndarray:
        """The ranges `(B,)` [m] a noise-free laser reads at the true pose (what `scan` adds
        its noise to; for audits of what the robot believed against what was there). Draws
        no random numbers."""
        laser = self.params.laser
        return cast_scan_skip(
            self._jump,
            self._res,
            self._ox,
            self._oy,
            self._x,
            self._y,
            self._th,
            self._angles,
            laser.range_max,
        )
