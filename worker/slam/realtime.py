"""Real-time emulation: every SLAM update takes simulated time, as under ROS.

`RealtimeSlam` wraps any in-process algorithm. An update started on the scan of time t is
published at t + its compute time: until then the robot drives on the last published pose
(that estimate moved on by the odometry since its scan, i.e. the last map->odom correction)
and the navigation reads the last published map; scans that arrive while the SLAM is busy are
dropped, as slam_gmapping's laser callback drops them (it is single-threaded, its message
queue short). The compute time comes from a deterministic cost model of the work the update
did (`update_cost_s`), never from a clock, so a seed gives the same run on any machine and
with any thread count.

An algorithm that splits its update (`advance`: move and gate, cheap; `update`: the work, as
`RbpfSlam` does) has the held-back update computed in a worker thread, beside the simulation
and navigation: it is started when its scan is taken and joined at its publication time in
simulated time at the latest, and nothing of the algorithm is read meanwhile (the robot drives
on the snapshot taken before it started), so the run is the one the update made in place
gives, bit for bit. The map of the last published update is built in that thread too, before
the update, and only waited for when something reads the map before the publication.
"""

from __future__ import annotations

import time
from concurrent.futures import Future, ThreadPoolExecutor
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
# whether a split update runs in a worker thread when the caller does not say (the same run
# either way; benchmarks/bench_realtime.py --overlap times both)
BACKGROUND = True


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

    def __init__(self, inner, params: RealtimeParams, n_beams: int, background: bool | None = None):
        """background: compute a split update (`advance` / `update`) in a worker thread (False:
        in place; the same run either way; None: BACKGROUND)."""
        background = BACKGROUND if background is None else background
        if params.fixed_latency_s is None:
            update_cost_s(inner, n_beams)  # refuses an algorithm without a cost model
        self._inner = inner
        self._split = background and hasattr(inner, "advance") and hasattr(inner, "update")
        self._pool: ThreadPoolExecutor | None = None
        self._job: Future | None = None  # the update in flight (in the worker thread)
        # [s] wall time of the worker's updates, and of the run's thread waiting for them (not
        # in the summary: the run does not depend on them)
        self.work_wall_s = 0.0
        self.wait_wall_s = 0.0
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
        # the published map (None: the inner's, nothing pending; a Future: being built)
        self._pub_grid = None

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
        if self._split and self.latency_s() > _EPS:
            self._start(t, pose_odom, ranges_m)
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

    def _start(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> None:
        """Gate the scan here; an update is computed in the worker thread, the estimate before
        it published until t + its latency (what `process` does in place, minus the map)."""
        est, odom, _ = self._snapshot(with_map=False)
        ranges = self._inner.advance(t, pose_odom, ranges_m)
        self._fed_now = True
        self._fed_odom = self._odom
        if ranges is None:
            return
        lat = self.latency_s()
        self.stats.updates += 1
        self.stats.latencies.append(lat)
        self._busy_until = t + lat
        self._pending = True
        self._pub_est, self._pub_odom = est, odom
        self._pub_grid = Future()
        if self._pool is None:
            self._pool = ThreadPoolExecutor(1, thread_name_prefix="realtime-slam")
        self._job = self._pool.submit(self._work, ranges, self._pub_grid)

    def _work(self, ranges: np.ndarray, grid: Future) -> None:
        """The worker thread: the map before the update (for a read while it is held back; the
        algorithm's own cache when the map was read since its last update), then the update."""
        t0 = time.perf_counter()
        try:
            grid.set_result(self._inner.occupancy())
        except BaseException as exc:  # the reader sees it, and so does the join
            grid.set_exception(exc)
            raise
        self._inner.update(ranges)
        self.work_wall_s += time.perf_counter() - t0

    def _join(self) -> None:
        """Wait for the update in flight (its error raised here, in the run's thread)."""
        job, self._job = self._job, None
        if job is not None:
            t0 = time.perf_counter()
            try:
                job.result()
            finally:
                self.wait_wall_s += time.perf_counter() - t0

    def _snapshot(self, with_map: bool = True) -> tuple[np.ndarray, np.ndarray, object]:
        """(estimate, the odometry it was made at, map) published now, before the inner
        processes the next scan (before the first scan: the map frame is the odometry's)."""
        grid = self._inner.occupancy() if with_map else None
        if self._fed_odom is None:
            return self._odom.copy(), self._odom.copy(), grid
        est = np.asarray(self._inner.pose_estimate(), dtype=float)
        return est, self._fed_odom.copy(), grid

    def _publish(self) -> None:
        self._join()
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
        if self._pub_grid is None:
            return self._inner.occupancy()
        if isinstance(self._pub_grid, Future):  # the worker thread builds it first
            self._pub_grid = self._pub_grid.result()
        return self._pub_grid

    def occupancy_with_hits(self):
        # the run's final map: the last update's, published or not (the run is over)
        self._join()
        return getattr(self._inner, "occupancy_with_hits", self._inner.occupancy)()

    def close(self) -> None:
        try:
            self._join()
        finally:
            if self._pool is not None:
                self._pool.shutdown()
            close = getattr(self._inner, "close", None)
            if close is not None:
                close()
