"""The protocol twin of an in-process algorithm: `python -m worker.slam.external.twin odometry`
serves worker.slam's algorithm over stdin / stdout, for benchmarks and tests of the protocol.
For an algorithm whose scans between updates change nothing but the pose (GATED), its ready
asks mapqual to send only the scans past GMapping's gate; `--every-scan` takes them all.

It answers every step with the algorithm's pose and whether the map changed, and a map request
with the cells that changed since the map it sent last (float32 patches; the whole map when
its extent changed): the map is built only when mapqual reads it, as in-process, and a run
through the twin follows the same path as the in-process run, bit for bit.
"""

from __future__ import annotations

import os
import sys
from dataclasses import replace

import msgpack
import numpy as np

from worker.params import from_dict
from worker.slam.base import make_slam
from worker.slam.external import protocol as proto
from worker.slam.external.kernels import changed_box
from worker.slam.params import SlamParams

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
    """Map messages: the whole grid at first and when its extent changes, else one patch of
    the cells that changed since the last message (None when none did)."""

    def __init__(self) -> None:
        self._last = None  # the OccupancyGrid of the last message

    def message(self, grid) -> dict | None:
        h, w = grid.shape
        m = {
            "resolution": grid.resolution, "origin": [float(v) for v in grid.origin],
            "width": w, "height": h, "encoding": "float32",
        }  # fmt: skip
        last, self._last = self._last, grid
        same = last is not None and last.shape == grid.shape and last.resolution == grid.resolution
        if not (same and np.array_equal(last.origin, grid.origin)):
            m["data"] = _cells(grid.prob)
            return m
        # bit patterns: NaN (unknown) equals NaN; one compiled pass, no mask
        r0, r1, c0, c1 = changed_box(grid.prob.view(np.uint32), last.prob.view(np.uint32))
        if r0 < 0:
            return None
        data = _cells(grid.prob[r0:r1, c0:c1])
        m["patches"] = [{"col": c0, "row": r0, "width": c1 - c0, "height": r1 - r0, "data": data}]
        return m


def serve(algorithm: str, stdin: int, stdout: int, *, gate: bool = True) -> int:
    """Answer mapqual on the file descriptors `stdin` and `stdout` until `bye` or the end of
    input; the exit code. gate=False takes every scan, even for a GATED algorithm."""
    slam = None
    maps = MapSender()
    frames = FrameReader(stdin)
    while (msg := frames.next()) is not None:
        kind = msg["type"]
        if kind == "hello":
            out = {"type": "hello", "protocol": proto.PROTOCOL, "version": proto.VERSION}
            out["name"] = f"{algorithm} (protocol twin)"
        elif kind == "config":
            params = from_dict(SlamParams, msg["params"], "params")
            rng = np.random.default_rng(int(msg["seed"]))
            out = {"type": "ready"}
            if gate and algorithm in GATED:  # mapqual gates the scans: each one sent is an update
                out["gate"] = {
                    "linear_update": params.linear_update, "angular_update": params.angular_update,
                    "temporal_update": params.temporal_update,
                }  # fmt: skip
                params = replace(params, linear_update=0.0, angular_update=0.0)
            slam = make_slam(algorithm, _Laser(msg["laser"]), params, rng)
        elif kind == "step" and slam is not None:
            ranges = np.frombuffer(msg["ranges"], dtype="<f8")
            updated = slam.process(msg["t"], np.asarray(msg["odom"], dtype=float), ranges)
            pose = [float(v) for v in slam.pose_estimate()]
            T = [float(v) for v in slam.T_map_odom()]
            out = {"type": "estimate", "seq": msg["seq"], "pose": pose, "T_map_odom": T}
            out["updated"] = bool(updated)
        elif kind == "map" and slam is not None:
            out = {"type": "map", "map": maps.message(slam.occupancy())}
        elif kind == "bye":
            return 0
        else:
            out = {"type": "error", "message": f"unexpected {kind!r} message"}
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
    code = serve(args[0], sys.stdin.fileno(), sys.stdout.fileno(), gate=not every)
    os._exit(code)  # at once: the interpreter's own shutdown (numba, LLVM) takes a second


if __name__ == "__main__":
    main()
