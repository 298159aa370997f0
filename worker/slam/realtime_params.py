"""RealtimeParams: the run option under which every SLAM update takes simulated time (light:
no kernels imported, so the API validates a job's params without the numeric stack)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from worker.errors import InputError

# The thesis's computer against the cost model's calibration machine (a 2.6 GHz Xeon cloud
# VM): the thesis ran on a Core2 Quad Q9400 at 2.66 GHz (its section 6.3.1; issue 51's "2018
# laptop" is the thesis's academic year). Published single-thread scores put such a Penryn
# core at 0.29-0.37 of a Skylake-class core (docs/howto/realtime.md, with sources), so at
# equal work per particle x beam an update there takes about 1 / 0.35 as long: 0.50 s for
# the thesis's 40-particle update (0.173 s modelled at speed 1). The upper end of the range
# the thesis's own account allows (GMapping rarely saturating the CPU) is 1.0; see the page.
THESIS_PC_SPEED = 0.35
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
