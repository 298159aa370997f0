"""Real-time emulation: every SLAM update takes simulated time, as under ROS.

`RealtimeSlam` wraps any in-process algorithm. An update started on the scan of time t is
published at t + its compute time: until then the robot drives on the last published pose
(that estimate moved on by the odometry since its scan, i.e. the last map->odom correction)
and the navigation reads the last published map; scans that arrive while the SLAM is busy are
dropped, as slam_gmapping's laser callback drops them (it is single-threaded, its message
queue short). The compute time comes from a deterministic cost model of the work the update
did (`update_cost_s`), never from a clock, so a seed gives the same run on any machine and
with any thread count.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from worker.errors import InputError
from worker.evaluate.se2 import compose, inverse
from worker.slam.realtime_params import RealtimeParams

# The cost model, calibrated once (benchmarks/calibrate_realtime.py --scans 800, 2026-12-06,
# Freiburg 079's first 800 scans, threads 1, particles 10 / 20 / 40, lskip 0 / 1, this thread's
# CPU time on a 2-core Intel Xeon cloud host): an rbpf update's CPU time [s] = RBPF_C0 +
# RBPF_C1 * particles * used beams * (iterations + 1) (largest error of the fit 21 %); an
# odometry-only update's (one scan into the map) = ODOM_C0 + ODOM_C1 * beams (4 %).
RBPF_C0 = 5.975e-3  # [s]
RBPF_C1 = 1.289e-6  # [s] per particle x used beam x (iterations + 1)
ODOM_C0 = 1.043e-4  # [s]
ODOM_C1 = 8.899e-7  # [s] per beam
_EPS = 1e-9  # [s] time stamps on the 0.1 s grid compare with this slack


def update_cost_s(slam, n_beams: int) -> float:
    """[s] the modelled CPU time, on the calibration machine, of the update `slam` just made."""
    name = getattr(slam, "name", "")
    if name == "rbpf":
        p = slam.params
        used = -(-n_beams // (p.lskip + 1))  # ceil: beams 0, lskip+1, ...
        return RBPF_C0 + RBPF_C1 * p.particles * used * (p.iterations + 1)
    if name == "odometry":
        return ODOM_C0 + ODOM_C1 * n_beams
    raise InputError(f"no real-time cost model for SLAM algorithm {name!r}")


@dataclass
class RealtimeStats:
    """What the summary reports: updates made, scans dropped, update latencies [s]."""

    scans: int = 0
    updates: int = 0
    dropped: int = 0
    latencies: list[float] = field(default_factory=list)

    def summary(self, speed: float, fixed: float | None) -> dict:
        lat = np.asarray(self.latencies, dtype=float)
        return {
            "speed": speed,
            "fixed_latency_s": fixed,
            "scans": self.scans,
            "updates": self.updates,
            "scans_dropped": self.dropped,
            "latency_mean_s": float(lat.mean()) if lat.size else 0.0,
            "latency_max_s": float(lat.max()) if lat.size else 0.0,
        }


class RealtimeSlam:
    """`inner` with ROS's timing; the SlamAlgorithm interface (worker.slam.base)."""

    def __init__(self, inner, params: RealtimeParams, n_beams: int):
        if params.fixed_latency_s is None:
            update_cost_s(inner, n_beams)  # refuses an algorithm without a cost model
        self._inner = inner
        self.name = inner.name
        self.params = params
        self._n_beams = n_beams
        self.stats = RealtimeStats()
        self._busy_until = -np.inf  # [s] when the update in progress publishes
        self._pending = False  # an update computed but not yet published
        self._odom = np.zeros(3)  # the latest odometry pose given
        self._fed_odom: np.ndarray | None = None  # that of the last scan the inner processed
        self._fed_now = False  # whether the latest scan was processed (not dropped)
        self._pub_est = np.zeros(3)  # the published estimate, at its scan's odometry:
        self._pub_odom = np.zeros(3)
        self._pub_grid = None  # the published map (None: the inner's, nothing pending)

    def latency_s(self) -> float:
        """[s] how long the update just made takes on the robot's computer."""
        fixed = self.params.fixed_latency_s
        if fixed is not None:
            return fixed
        return update_cost_s(self._inner, self._n_beams) / self.params.speed

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        """Feed one scan; True when a map / pose was published at this step (an update that
        finished by now, or an instant one)."""
        self.stats.scans += 1
        self._odom = np.asarray(pose_odom, dtype=float)
        published = False
        self._fed_now = False
        if self._pending and t >= self._busy_until - _EPS:
            self._publish()
            published = True
        if t < self._busy_until - _EPS:  # still busy: ROS drops this scan
            self.stats.dropped += 1
            return published
        before = self._snapshot()
        updated = self._inner.process(t, pose_odom, ranges_m)
        self._fed_now = True
        self._fed_odom = self._odom
        if not updated:
            return published
        lat = self.latency_s()
        self.stats.updates += 1
        self.stats.latencies.append(lat)
        if lat <= _EPS:  # instant: the inner's state is the published one
            return True
        self._busy_until = t + lat
        self._pending = True
        self._pub_est, self._pub_odom, self._pub_grid = before
        return published

    def _snapshot(self) -> tuple[np.ndarray, np.ndarray, object]:
        """(estimate, the odometry it was made at, map) published now, before the inner
        processes the next scan (before the first scan: the map frame is the odometry's)."""
        if self._fed_odom is None:
            return self._odom.copy(), self._odom.copy(), self._inner.occupancy()
        est = np.asarray(self._inner.pose_estimate(), dtype=float)
        return est, self._fed_odom.copy(), self._inner.occupancy()

    def _publish(self) -> None:
        self._pending = False
        self._pub_grid = None

    def _base(self) -> tuple[np.ndarray, np.ndarray]:
        """(published estimate, the odometry it was made at)."""
        if self._pending:
            return self._pub_est, self._pub_odom
        if self._fed_odom is None:
            return self._odom, self._odom
        return np.asarray(self._inner.pose_estimate(), dtype=float), self._fed_odom

    def pose_estimate(self) -> np.ndarray:
        if not self._pending and self._fed_now:
            return self._inner.pose_estimate()
        # the last published estimate moved on by the odometry since its scan: map->odom x odom
        est, odom = self._base()
        return compose(est, compose(inverse(odom), self._odom))

    def T_map_odom(self) -> np.ndarray:
        if not self._pending and self._fed_now:
            return self._inner.T_map_odom()
        est, odom = self._base()
        return compose(est, inverse(odom))

    def occupancy(self):
        return self._inner.occupancy() if self._pub_grid is None else self._pub_grid

    def occupancy_with_hits(self):
        # the run's final map: the last update's, published or not (the run is over)
        return getattr(self._inner, "occupancy_with_hits", self._inner.occupancy)()

    def close(self) -> None:
        close = getattr(self._inner, "close", None)
        if close is not None:
            close()
