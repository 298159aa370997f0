"""The protocol twin of an in-process algorithm: `python -m worker.slam.external.twin odometry`
serves worker.slam's algorithm over stdin / stdout, for benchmarks and tests of the protocol.
For an algorithm whose scans between updates change nothing but the pose (GATED), its ready
asks mapqual to send only the scans past GMapping's gate; `--every-scan` takes them all.

It answers every step with the algorithm's pose and whether the map changed, and a map request
with the cells that changed since the map it sent last (version 2: their list or their box,
whichever is smaller; version 1: their box, the whole map when its extent changed): the map
is built only when mapqual reads it, as in-process, and a run through the twin follows the
same path as the in-process run, bit for bit.
"""

from __future__ import annotations

import os
import sys
from dataclasses import replace

# One thread of BLAS before numpy loads it: the twin is single-threaded, and OpenBLAS's pool
# of spinning threads costs a third of its start-up's CPU (0.25 of 0.8 s, measured) for no use.
# A run's program is started anew each run, so that start-up counts.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import msgpack  # noqa: E402
import numpy as np  # noqa: E402

from worker.param_io import from_dict  # noqa: E402
from worker.slam.base import beam_angles, beam_limits  # noqa: E402
from worker.slam.external import protocol as proto  # noqa: E402
from worker.slam.external.kernels import changed_box, changed_cells  # noqa: E402
from worker.slam.external.mapmsg import placed  # noqa: E402
from worker.slam.params import SlamParams  # noqa: E402
from worker.slam.registry import make_slam  # noqa: E402

# algorithms whose scans between updates change nothing but the pose (T_map_odom (+) odom):
# the twin lets mapqual gate them (rbpf draws its motion model at every scan, graph SLAM keeps
# its own node spacing: both are sent every scan)
GATED = frozenset({"odometry"})


class _Laser:
    """The laser geometry of a `config` message."""

    def __init__(self, laser: dict):
        self.n_beams = int(laser["n_beams"])
        self.angle_min = float(laser["angle_min"])
        self.angle_increment = float(laser["angle_increment"])
        self.range_max = float(laser["range_max"])


class FrameReader:
    """Frames from a file descriptor: one read() call for the usual frame, header and all
    (a buffered stream's read(4) then read(n) makes two)."""

    def __init__(self, fd: int):
        self.fd = fd
        self._buf = bytearray()

    def _fill(self, n: int) -> bool:
        """Whether `n` bytes are buffered (False: the input ended first)."""
        while len(self._buf) < n:
            chunk = os.read(self.fd, max(1 << 16, n - len(self._buf)))
            if not chunk:
                return False
            self._buf += chunk
        return True

    def next(self) -> dict | None:
        """The next message, None at the end of the input."""
        size = proto.HEADER.size
        if not self._fill(size):
            return None
        (n,) = proto.HEADER.unpack_from(self._buf)
        if not self._fill(size + n):
            return None
        with memoryview(self._buf) as view:
            message = proto.unpack(view[size : size + n])
        del self._buf[: size + n]
        return message


def write_frame(fd: int, message: dict) -> None:
    """Write one frame: header and payload in one writev() call, no joined copy."""
    payload = msgpack.packb(message, use_bin_type=True)
    parts = [proto.HEADER.pack(len(payload)), payload]
    left = len(parts[0]) + len(payload)
    while left:
        n = os.writev(fd, parts)
        left -= n
        while parts and n >= len(parts[0]):  # drop what was written
            n -= len(parts[0])
            parts.pop(0)
        if n:
            parts[0] = memoryview(parts[0])[n:]


def _cells(a: np.ndarray) -> memoryview:
    """The bytes of float32 cells, little-endian, without a copy when `a` is contiguous."""
    return np.ascontiguousarray(a, dtype="<f4").data.cast("B")


class MapSender:
    """Map messages: the whole grid at first (and when its resolution or alignment changes),
    else what changed since the last message (None when nothing did): with version 2 the
    changed cells' list or their bounding box, whichever is fewer bytes (the list costs 8
    bytes a cell, the box 4 a cell of it; a scan changes few cells over a wide box: the
    walls it hit and the unknown it saw), the previous cells moved by whole cells when the
    map grew; with version 1 the box, and the whole grid when the extent changed."""

    def __init__(self, version: int = 1) -> None:
        self.version = version
        self._last = None  # the OccupancyGrid of the last message
        self._index = np.empty(0, dtype="<u4")  # the changed cells' indices, reused

    def message(self, grid, within: tuple[float, ...] | None = None) -> dict | None:
        """The message for `grid`; within: (x0, y0, x1, y1) [m] the region outside which no
        cell can have changed since the last message (None: anywhere), where the cells are
        compared when the extent did not change (version 2)."""
        h, w = grid.shape
        m = {
            "resolution": grid.resolution, "origin": [float(v) for v in grid.origin],
            "width": w, "height": h, "encoding": "float32",
        }  # fmt: skip
        last, self._last = self._last, grid
        before = self._before(last, grid)
        if before is None:
            m["data"] = _cells(grid.prob)
            return m
        if self.version < 2:
            # bit patterns: NaN (unknown) equals NaN; one compiled pass, no mask
            r0, r1, c0, c1 = changed_box(grid.prob.view(np.uint32), before.view(np.uint32))
            n = 1 if r0 >= 0 else 0
        else:
            n, r0, r1, c0, c1 = self._changed(grid, before, within if before is last.prob else None)
        if n == 0:
            return None
        if self.version >= 2 and 8 * n < 4 * (r1 - r0) * (c1 - c0):
            index = self._index[:n]
            m["cells"] = {"index": index.data, "data": _cells(grid.prob.reshape(-1)[index])}
            return m
        data = _cells(grid.prob[r0:r1, c0:c1])
        m["patches"] = [{"col": c0, "row": r0, "width": c1 - c0, "height": r1 - r0, "data": data}]
        return m

    def _changed(self, grid, before: np.ndarray, within) -> tuple[int, int, int, int, int]:
        """changed_cells over the whole grid, or over the cells of `within` (see message)."""
        h, w = grid.shape
        r0, r1, c0, c1 = 0, h, 0, w
        if within is not None:  # one cell more all round: the kernels' rounding
            lo = np.floor((np.asarray(within[:2]) - grid.origin) / grid.resolution) - 1
            hi = np.floor((np.asarray(within[2:]) - grid.origin) / grid.resolution) + 2
            c0, r0 = (int(v) for v in np.maximum(lo, 0))
            c1, r1 = int(min(hi[0], w)), int(min(hi[1], h))
            if r1 <= r0 or c1 <= c0:
                return 0, -1, -1, -1, -1
        if self._index.shape[0] < (r1 - r0) * (c1 - c0):
            self._index = np.empty(h * w, dtype="<u4")
        a, b = grid.prob.view(np.uint32), before.view(np.uint32)
        return changed_cells(a[r0:r1, c0:c1], b[r0:r1, c0:c1], self._index, r0, c0, w)

    def _before(self, last, grid) -> np.ndarray | None:
        """The last map's cells in `grid`'s extent (None: send the whole grid)."""
        if last is None or last.resolution != grid.resolution:
            return None
        if last.shape == grid.shape and np.array_equal(last.origin, grid.origin):
            return last.prob
        if self.version < 2:
            return None
        try:  # the map grew: its old cells moved by whole cells, as mapqual will move them
            return placed(last, grid.resolution, grid.origin, *grid.shape)
        except proto.ProtocolError:  # moved by a fraction of a cell
            return None


class _Reach:
    """The region a GATED algorithm's scans can have changed: GMapping's registration writes
    the cells of each beam from the robot to its end point (at most the usable range, beams
    past max_range skipped), so the box of the scan poses and those end points holds every
    cell the scans since the last map message touched."""

    def __init__(self, laser: _Laser, params: SlamParams):
        angles = beam_angles(laser)  # as the algorithm's own registration has them
        self._cos, self._sin = np.cos(angles), np.sin(angles)
        self._max_range, self._usable = beam_limits(laser, params)
        self.box: list[float] | None = None  # [x0, y0, x1, y1] [m], None: nothing yet

    def add(self, pose: np.ndarray, ranges: np.ndarray) -> None:
        ok = (ranges > 0.0) & (ranges <= self._max_range)
        d = np.minimum(ranges[ok], self._usable)
        c, s = np.cos(pose[2]), np.sin(pose[2])
        x = pose[0] + d * (c * self._cos[ok] - s * self._sin[ok])
        y = pose[1] + d * (s * self._cos[ok] + c * self._sin[ok])
        box = [x.min(initial=pose[0]), y.min(initial=pose[1]),
               x.max(initial=pose[0]), y.max(initial=pose[1])]  # fmt: skip
        if self.box is not None:
            box = [min(box[0], self.box[0]), min(box[1], self.box[1]),
                   max(box[2], self.box[2]), max(box[3], self.box[3])]  # fmt: skip
        self.box = box

    def take(self) -> tuple[float, ...] | None:
        """The box since the last call, then start anew."""
        box, self.box = self.box, None
        return None if box is None else tuple(box)


class Twin:
    """One program's state: the answer to each message (None for `bye`)."""

    def __init__(self, algorithm: str, *, gate: bool = True):
        self.algorithm, self.gate = algorithm, gate
        self.slam = None
        self.maps = MapSender(1)
        self._reach: _Reach | None = None  # GATED algorithms: where their map can change

    def answer(self, msg: dict) -> dict | None:
        kind = msg["type"]
        if kind == "hello":  # the newest version both speak
            offered = msg.get("versions", [])
            version = max((v for v in proto.VERSIONS if v in offered), default=proto.VERSIONS[0])
            self.maps = MapSender(version)
            out = {"type": "hello", "protocol": proto.PROTOCOL, "version": version}
            out["name"] = f"{self.algorithm} (protocol twin)"
        elif kind == "config":
            out = self._configure(msg)
        elif kind == "step" and self.slam is not None:
            ranges = np.frombuffer(msg["ranges"], dtype="<f8")
            odom = np.asarray(msg["odom"], dtype=float)
            updated = self.slam.process(msg["t"], odom, ranges)
            if updated and self._reach is not None:
                self._reach.add(odom, ranges)
            pose = [float(v) for v in self.slam.pose_estimate()]
            T = [float(v) for v in self.slam.T_map_odom()]
            out = {"type": "estimate", "seq": msg["seq"], "pose": pose, "T_map_odom": T}
            out["updated"] = bool(updated)
            if updated and msg.get("map_due"):  # read at once: with the estimate
                m = self._map()
                if m is not None:
                    out["map"] = m
        elif kind == "map" and self.slam is not None:
            out = {"type": "map", "map": self._map()}
        elif kind == "bye":
            return None
        else:
            out = {"type": "error", "message": f"unexpected {kind!r} message"}
        return out

    def _map(self) -> dict | None:
        """The map message for the current map (None: unchanged since the last)."""
        within = None if self._reach is None else self._reach.take()
        return self.maps.message(self.slam.occupancy(), within)

    def _configure(self, msg: dict) -> dict:
        params = from_dict(SlamParams, msg["params"], "params")
        rng = np.random.default_rng(int(msg["seed"]))
        laser = _Laser(msg["laser"])
        out: dict = {"type": "ready"}
        self._reach = None
        if self.algorithm in GATED:
            # its map is the scans registered at the odometry (T_map_odom = 0) and nothing else
            self._reach = _Reach(laser, params)
            if self.gate:  # mapqual gates the scans: each one sent is an update
                out["gate"] = {
                    "linear_update": params.linear_update, "angular_update": params.angular_update,
                    "temporal_update": params.temporal_update,
                }  # fmt: skip
                params = replace(params, linear_update=0.0, angular_update=0.0)
        self.slam = make_slam(self.algorithm, laser, params, rng)
        return out


def warm_up(algorithm: str) -> None:
    """Answer a made-up run of two scans, as mapqual's frames would bring them, so that the
    compiled kernels load now, while mapqual sets its run up (the program's own start-up,
    overlapped), not at the first real scan."""
    twin = Twin(algorithm)
    laser = {"n_beams": 541, "angle_min": -2.356, "angle_increment": 0.0087, "range_max": 30.0}
    ranges = np.linspace(1.0, 31.0, laser["n_beams"])
    for msg in (
        {"type": "hello", "versions": list(proto.VERSIONS)},
        {"type": "config", "laser": laser, "params": {}, "seed": 0},
        {"type": "step", "seq": 0, "t": 0.0, "odom": [0.0, 0.0, 0.0], "ranges": ranges},
        {"type": "map"},
        {"type": "step", "seq": 1, "t": 0.1, "odom": [0.5, 0.0, 0.1], "ranges": ranges * 0.9},
        {"type": "map"},
    ):
        # through msgpack: the arrays arrive as read-only bytes, as mapqual's do
        twin.answer(proto.unpack(msgpack.packb(_wire(msg), use_bin_type=True)))


def _wire(msg: dict) -> dict:
    return {
        k: (v.astype("<f8").tobytes() if isinstance(v, np.ndarray) else v) for k, v in msg.items()
    }


def serve(algorithm: str, stdin: int, stdout: int, *, gate: bool = True) -> int:
    """Answer mapqual on the file descriptors `stdin` and `stdout` until `bye` or the end of
    input; the exit code. gate=False takes every scan, even for a GATED algorithm."""
    twin = Twin(algorithm, gate=gate)
    frames = FrameReader(stdin)
    while (msg := frames.next()) is not None:
        out = twin.answer(msg)
        if out is None:
            return 0
        write_frame(stdout, out)
    return 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    every = "--every-scan" in args
    args = [a for a in args if a != "--every-scan"]
    if len(args) != 1:
        usage = "usage: python -m worker.slam.external.twin ALGORITHM [--every-scan]"
        print(usage, file=sys.stderr)
        return 2
    warm_up(args[0])
    code = serve(args[0], sys.stdin.fileno(), sys.stdout.fileno(), gate=not every)
    os._exit(code)  # at once: the interpreter's own shutdown (numba, LLVM) takes a second


if __name__ == "__main__":
    main()
