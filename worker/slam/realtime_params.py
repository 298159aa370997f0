"""RealtimeParams: the run option under which every SLAM update takes simulated time (light:
no kernels imported, so the API validates a job's params without the numeric stack)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from worker.errors import InputError

# The thesis's computer against the cost model's calibration machine: the speed at which a
# 40-particle update of the thesis's laser (541 beams, GMapping's 5 iterations) takes 0.5 s,
# "a good part of a second" as issue 51 puts it (0.173 s modelled at speed 1). An assumption,
# not a measurement: the thesis ran on a Core2 Quad Q9400 (2008) and reports GMapping at
# about 40 % CPU on average (its section 6.2). A user gives their own computer's factor.
LAPTOP_2018_SPEED = 0.35
# the algorithms with a cost model (worker.slam.realtime.update_cost_s); the others run under
# the option only with a fixed latency
MODELLED = ("rbpf", "odometry")


@dataclass(frozen=True)
class RealtimeParams:
    """ROS-like real-time SLAM: an update started on a scan at t publishes its pose and map at
    t + its compute time; the robot drives on the last published ones meanwhile, and scans
    that arrive while the SLAM is busy are dropped (as slam_gmapping's laser callback does).

    speed: the robot computer's speed relative to the machine the cost model was calibrated on
    (0.5 = half as fast: every update takes twice as long). fixed_latency_s: instead of the
    cost model, every update takes exactly this long [s] (0 = today's instant SLAM).
    """

    speed: float = 1.0
    fixed_latency_s: float | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise InputError(f"realtime.speed must be a finite number > 0, got {self.speed}")
        lat = self.fixed_latency_s
        if lat is not None and not (math.isfinite(lat) and lat >= 0):
            raise InputError(f"realtime.fixed_latency_s must be >= 0 [s], got {lat}")
