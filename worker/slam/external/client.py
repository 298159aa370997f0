"""ExternalSlam: a SlamAlgorithm whose work is done by a child program over the protocol."""

from __future__ import annotations

import contextlib
import math
import sys
import time
from dataclasses import replace
from typing import Any

import numpy as np

from worker.errors import InputError, SlamFailed
from worker.param_io import to_dict
from worker.slam.base import LaserGeometry
from worker.slam.external import protocol as proto
from worker.slam.external.mapmsg import read_map
from worker.slam.external.process import ChildGone, ChildProcess
from worker.slam.gating import UpdateGate
from worker.slam.grid import OccupancyGrid
from worker.slam.motion import compose3
from worker.slam.params import SlamParams


class ExternalSlam:
    """Starts the program and says hello when made (so that the program's own start-up, an
    interpreter, its imports, a model loaded, overlaps the run's set-up), reads its answer
    and sends the config at the first scan, then one `step` frame and one `estimate` answer
    per scan; the map comes with an estimate, or is asked for (`map`) when it is read after an
    update that came without it. Any failure (exit, time-out, bad answer) raises SlamFailed
    naming the step, once the program is stopped (a failed map request: at the next scan); the
    pose and map stay those of the last good answer."""

    name = "external"

    def __init__(self, laser: LaserGeometry, params: SlamParams, rng: np.random.Generator):
        ext = params.external
        if ext is None or not ext.command:
            raise InputError("algorithm 'external' needs slam.external.command (the program)")
        self.ext = ext
        self.params = params
        geometry = {
            "n_beams": int(laser.n_beams), "angle_min": float(laser.angle_min),
            "angle_increment": float(laser.angle_increment), "range_max": float(laser.range_max),
        }  # fmt: skip
        self._n_beams = geometry["n_beams"]
        seed = int(rng.integers(2**63 - 1))  # for a program that draws random numbers
        own = to_dict(replace(params, external=None))
        self._config = {"type": "config", "laser": geometry, "params": own, "seed": seed}
        self._child: ChildProcess | None = None
        self._seq = 0
        self._started = False  # the handshake is done
        self._map_stale = False  # an update came without its map: ask for it when it is read
        self._t = 0.0  # [s] of the latest step
        self._pose = np.zeros(3)
        self._T = np.zeros(3)
        empty = np.full((1, 1), np.nan, dtype=np.float32)
        self._grid = OccupancyGrid(empty, params.delta, np.zeros(2), params.occ_thresh)
        self.program_name = ""  # as the program's hello gave it
        self.version = 0  # the protocol version the program chose (0: not started)
        self.updates = 0
        self.failure: SlamFailed | None = None
        self.protocol_wall_s = 0.0  # [s] spent waiting for, reading and writing frames
        self._gate: UpdateGate | None = None  # the program's update gate, from its ready
        self._trail: list[float] = []  # [t, x, y, theta] of the steps not sent since the last
        self._spawn_error: ChildGone | None = None  # the program could not be started
        self._map_due = False  # the next scan's map will be read if it is an update
        self._spawn()

    @property
    def pid(self) -> int | None:
        """The running program's process id (None when it could not start, and once closed)."""
        return None if self._child is None or self._child.closed else self._child.pid

    def process(self, t: float, pose_odom: np.ndarray, ranges_m: np.ndarray) -> bool:
        if self.failure is not None:
            raise self.failure
        seq, self._t = self._seq, float(t)
        try:
            if not self._started:
                self._start()
            child = self._child
            assert child is not None
            t0 = time.perf_counter()
            ranges = np.asarray(ranges_m, dtype=np.float64).reshape(-1)
            if ranges.shape[0] != self._n_beams:
                raise InputError(f"a scan has {ranges.shape[0]} beams, not {self._n_beams}")
            gate = self._gate
            if gate is not None and not gate.step(self._t, np.asarray(pose_odom, dtype=float)):
                # not sent: the program's map -> odom correction stays, as ROS's tf does
                self._trail.extend((self._t, pose_odom[0], pose_odom[1], pose_odom[2]))
                self._pose = compose3(self._T, np.asarray(pose_odom, dtype=np.float64))
                self._seq += 1
                self.protocol_wall_s += time.perf_counter() - t0
                return False
            deadline = time.monotonic() + self.ext.step_timeout_s
            trail = None
            if gate is not None:
                trail, self._trail = np.array(self._trail, dtype="<f8"), []
            due = self._map_due and self.version >= 2
            child.send(proto.step(seq, t, pose_odom, ranges, trail, map_due=due), deadline)
            answer = child.recv_message(deadline)
            self.protocol_wall_s += time.perf_counter() - t0
            updated = self._read_estimate(answer, seq, np.asarray(pose_odom, dtype=np.float64))
        except (ChildGone, proto.ProtocolError) as exc:
            raise self._fail(seq, t, exc) from None
        self._seq += 1
        self.updates += updated
        self._map_due = False
        return updated

    def will_read_map(self, due: bool) -> None:
        """The caller says, before the next `process`, whether it will read the map if that
        scan updates it: a program speaking version 2 is then asked to attach the map to its
        estimate (`map_due`), which spares the `map` request's round trip."""
        self._map_due = bool(due)

    def _spawn(self) -> None:
        """Start the program and send mapqual's hello (a failure is raised at the first scan,
        as a failed start-up)."""
        try:
            self._child = ChildProcess(
                self.ext.command, memory_mb=self.ext.memory_mb or 0, cpu_s=self.ext.cpu_s or 0
            )
            # a few bytes into an empty pipe: never waits
            self._child.send(
                proto.frame(proto.hello()), time.monotonic() + self.ext.start_timeout_s
            )
        except ChildGone as exc:
            self._spawn_error = exc

    def _start(self) -> None:
        """The program's hello, then the laser and parameters and its ready, within
        start_timeout_s of the first scan."""
        if self._spawn_error is not None:
            raise self._spawn_error
        child = self._child
        assert child is not None
        deadline = time.monotonic() + self.ext.start_timeout_s
        self.program_name, self.version = proto.check_hello(child.recv_message(deadline))
        child.send(proto.frame(self._config), deadline)
        ready = child.recv_message(deadline)
        proto.expect(ready, "ready")
        if ready.get("gate") is not None:
            linear, angular, temporal = proto.gate(ready["gate"])
            self._gate = UpdateGate(linear, angular, temporal)
        self._started = True

    def _read_estimate(self, msg: dict[str, Any], seq: int, pose_odom: np.ndarray) -> bool:
        """Take an estimate's pose, correction and map; whether the map changed."""
        proto.expect(msg, "estimate")
        if msg.get("seq") != seq:
            raise proto.ProtocolError(f"the estimate answers seq {msg.get('seq')!r}, not {seq}")
        pose = proto.pose3(msg, "pose")
        T = proto.pose3(msg, "T_map_odom") if "T_map_odom" in msg else _correction(pose, pose_odom)
        has_map = msg.get("map") is not None
        updated = msg.get("updated", has_map)
        if not isinstance(updated, bool):
            raise proto.ProtocolError(f"'updated' must be true or false, got {updated!r}")
        # the map last: it may be written into the current grid's cells, once all else is good
        grid = self._read_map(msg["map"]) if has_map else None
        self._pose, self._T = pose, T
        if grid is not None:
            self._grid = grid
        self._map_stale = grid is None and (updated or self._map_stale)
        return updated

    def _fail(self, seq: int, t: float, exc: Exception) -> SlamFailed:
        """Stop the program and make the one-line failure of step `seq`."""
        tail = self._child.stderr_tail() if self._child is not None else ""
        self.close()
        if self._child is not None:
            tail = self._child.stderr_tail() or tail
        kind = "protocol error" if isinstance(exc, proto.ProtocolError) else "failed"
        where = f"at step {seq} (t={t:.2f} s)" if self._started else "at start-up"
        message = f"external SLAM {self.ext.name!r} {kind} {where}: {exc}"
        if tail:
            message += " | stderr: " + " | ".join(tail.splitlines()[-5:])
        self.failure = SlamFailed(message, seq if self._started else None, tail)
        return self.failure

    def pose_estimate(self) -> np.ndarray:
        return self._pose.copy()

    def T_map_odom(self) -> np.ndarray:
        return self._T.copy()

    def occupancy(self) -> OccupancyGrid:
        if self._map_stale and self.failure is None:
            self._map_stale = False
            try:
                self._fetch_map()
            except (ChildGone, proto.ProtocolError) as exc:  # raised at the next scan
                self._fail(self._seq - 1, self._t, proto.ProtocolError(f"map request: {exc}"))
        return self._grid

    def _fetch_map(self) -> None:
        """Ask for the map of the latest update (None in the answer: unchanged)."""
        child = self._child
        assert child is not None
        t0 = time.perf_counter()
        deadline = time.monotonic() + self.ext.step_timeout_s
        child.send(proto.frame({"type": "map"}), deadline)
        answer = child.recv_message(deadline)
        self.protocol_wall_s += time.perf_counter() - t0
        proto.expect(answer, "map")
        if answer.get("map") is not None:
            self._grid = self._read_map(answer["map"])

    def _read_map(self, m: Any) -> OccupancyGrid:
        """The grid a map message describes over the current one, whose cells are written in
        place when nobody else holds that grid or its cells (no whole-grid copy per map: the
        costmap reads the map and lets it go, a grid kept elsewhere is copied first)."""
        reuse = _sole_reference(self._grid)
        return read_map(m, self._grid, self.params.occ_thresh, version=self.version, reuse=reuse)

    def close(self) -> None:
        """Say bye and stop the program (killed past close_timeout_s); safe to call twice."""
        child = self._child
        if child is None or child.closed:
            return
        with contextlib.suppress(ChildGone):
            child.send(proto.frame({"type": "bye"}), time.monotonic() + 0.5)
        child.close(self.ext.close_timeout_s)

    def __enter__(self) -> ExternalSlam:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        with contextlib.suppress(Exception):  # interpreter shutdown: nothing left to report to
            self.close()


def _sole_reference(grid: OccupancyGrid) -> bool:
    """Whether `grid` (held in an attribute) and its cells are referenced from nowhere else: no
    caller keeps the grid, its `prob`, or a view of it (a view holds its base). The reference
    count check numpy's own `ndarray.resize(refcheck=True)` makes; on an interpreter without
    reference counts the answer is False (copy)."""
    getrefcount = getattr(sys, "getrefcount", None)
    if getrefcount is None:
        return False
    # the grid: the attribute, this frame's argument and getrefcount's; its cells: the grid's
    # attribute and getrefcount's
    return getrefcount(grid) <= 3 and getrefcount(grid.prob) <= 2


def _correction(pose_map: np.ndarray, pose_odom: np.ndarray) -> np.ndarray:
    """T_map_odom with pose_map = T_map_odom (+) pose_odom (SE(2) composition)."""
    th = pose_map[2] - pose_odom[2]
    c, s = math.cos(th), math.sin(th)
    x = pose_map[0] - (c * pose_odom[0] - s * pose_odom[1])
    y = pose_map[1] - (s * pose_odom[0] + c * pose_odom[1])
    return np.array([x, y, math.atan2(math.sin(th), math.cos(th))])
