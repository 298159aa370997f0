"""SimParams: the simulated robot and its sensors (no kernels: the API imports it)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from worker.errors import InputError
from worker.robot import FOOTPRINT_M
from worker.sim.laser import LaserSpec


@dataclass(frozen=True)
class SimParams:
    """Simulator parameters (Pioneer 3-AT class robot, Hokuyo UTM-30LX laser, Stage odometry)."""

    dt: float = 0.1  # [s] public step; ground truth, odometry and laser at 1/dt = 10 Hz
    v_max: float = 1.0  # [m/s] forward speed limit (above the DWA's max_vel_x 0.85)
    v_min: float = -0.5  # [m/s] reverse speed limit (the safety controller backs off)
    w_max: float = 2.0  # [rad/s] turn rate limit (above the DWA's max_vel_theta 0.7)
    acc_lin: float = 1.5  # [m/s^2] the DWA's acc_lim_x
    acc_ang: float = 2.5  # [rad/s^2] the DWA's acc_lim_theta
    # [m] side of the square footprint: the one setting of the robot's size (the exploration's
    # footprint_half_m follows from it in RunParams; worlds check start poses with FOOTPRINT_M)
    footprint: float = FOOTPRINT_M
    laser: LaserSpec = field(default_factory=LaserSpec)
    laser_noise_sigma: float = 0.0  # [m] Gaussian range noise (thesis: 0, 0.1, 0.3)
    odom_model: Literal["stage", "gaussian"] = "stage"
    odom_error: tuple[float, float, float] = (0.01, 0.01, 0.02)  # Stage E for x, y, theta [-]
    # Gaussian model: [m/m] x/y error per metre, [rad/rad] theta per radian, [rad/m] theta per m
    odom_sigmas: tuple[float, float, float] = (0.02, 0.02, 0.01)

    def __post_init__(self) -> None:
        checks = [
            (self.dt > 0, "dt must be > 0"),
            (self.v_max > 0 and self.w_max > 0, "v_max and w_max must be > 0"),
            (self.v_min <= 0, "v_min must be <= 0"),
            (self.acc_lin > 0 and self.acc_ang > 0, "acceleration limits must be > 0"),
            (self.footprint > 0, "footprint must be > 0"),
            (self.laser_noise_sigma >= 0, "laser noise sigma must be >= 0"),
            (self.odom_model in ("stage", "gaussian"), "odom_model must be stage or gaussian"),
            (min(self.odom_error) >= 0 and min(self.odom_sigmas) >= 0, "odometry errors >= 0"),
        ]
        for ok, message in checks:
            if not ok:
                raise InputError(f"simulator parameters: {message}")
