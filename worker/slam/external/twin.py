"""The protocol twin of an in-process algorithm: `python -m worker.slam.external.twin odometry`
serves worker.slam's algorithm over stdin / stdout, for benchmarks and tests of the protocol.

It answers every step with the algorithm's pose and whether the map changed, and a map request
with the cells that changed since the map it sent last (float32 patches; the whole map when
its extent changed): the map is built only when mapqual reads it, as in-process, and a run
through the twin follows the same path as the in-process run, bit for bit.
"""

from __future__ import annotations

import os
import sys
from typing import BinaryIO

import numpy as np

from worker.params import from_dict
from worker.slam.base import make_slam
from worker.slam.external import protocol as proto
from worker.slam.params import SlamParams


class _Laser:
    """The laser geometry of a `config` message."""

    def __init__(self, laser: dict):
        self.n_beams = int(laser["n_beams"])
        self.angle_min = float(laser["angle_min"])
        self.angle_increment = float(laser["angle_increment"])
        self.range_max = float(laser["range_max"])


def read_frame(stream: BinaryIO) -> dict | None:
    """The next message on `stream`, None at its end."""
    header = stream.read(proto.HEADER.size)
    if len(header) < proto.HEADER.size:
        return None
    (n,) = proto.HEADER.unpack(header)
    return proto.unpack(stream.read(n))


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
            m["data"] = np.ascontiguousarray(grid.prob, dtype="<f4").tobytes()
            return m
        # bit patterns: NaN (unknown) equals NaN, and one comparison pass
        changed = grid.prob.view(np.uint32) != last.prob.view(np.uint32)
        rows = np.flatnonzero(changed.any(axis=1))
        if rows.size == 0:
            return None
        r0, r1 = int(rows[0]), int(rows[-1]) + 1
        cols = np.flatnonzero(changed[r0:r1].any(axis=0))  # only the rows that changed
        c0, c1 = int(cols[0]), int(cols[-1]) + 1
        data = np.ascontiguousarray(grid.prob[r0:r1, c0:c1], dtype="<f4").tobytes()
        m["patches"] = [{"col": c0, "row": r0, "width": c1 - c0, "height": r1 - r0, "data": data}]
        return m


def serve(algorithm: str, stdin: BinaryIO, stdout: BinaryIO) -> int:
    """Answer mapqual until `bye` or the end of input; the exit code."""
    slam = None
    maps = MapSender()
    while (msg := read_frame(stdin)) is not None:
        kind = msg["type"]
        if kind == "hello":
            out = {"type": "hello", "protocol": proto.PROTOCOL, "version": proto.VERSION}
            out["name"] = f"{algorithm} (protocol twin)"
        elif kind == "config":
            params = from_dict(SlamParams, msg["params"], "params")
            rng = np.random.default_rng(int(msg["seed"]))
            slam = make_slam(algorithm, _Laser(msg["laser"]), params, rng)
            out = {"type": "ready"}
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
        stdout.write(proto.frame(out))
        stdout.flush()
    return 0


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m worker.slam.external.twin ALGORITHM", file=sys.stderr)
        return 2
    code = serve(args[0], sys.stdin.buffer, sys.stdout.buffer)
    sys.stdout.flush()
    os._exit(code)  # at once: the interpreter's own shutdown (numba, LLVM) takes a second


if __name__ == "__main__":
    main()
