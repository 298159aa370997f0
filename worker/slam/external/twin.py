"""The protocol twin of an in-process algorithm: `python -m worker.slam.external.twin odometry`
serves worker.slam's algorithm over stdin / stdout, for benchmarks and tests of the protocol.

It answers every step with the algorithm's pose and, after an update, its whole map (float32),
so a run through the twin follows the same path as the in-process run, bit for bit.
"""

from __future__ import annotations

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


def map_message(slam) -> dict:
    """The algorithm's current grid as a whole-map message (float32, NaN unknown)."""
    grid = slam.occupancy()
    h, w = grid.shape
    return {
        "resolution": grid.resolution, "origin": [float(v) for v in grid.origin],
        "width": w, "height": h, "encoding": "float32",
        "data": np.ascontiguousarray(grid.prob, dtype="<f4").tobytes(),
    }  # fmt: skip


def serve(algorithm: str, stdin: BinaryIO, stdout: BinaryIO) -> int:
    """Answer mapqual until `bye` or the end of input; the exit code."""
    slam = None
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
            if updated:
                out["map"] = map_message(slam)
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
    return serve(args[0], sys.stdin.buffer, sys.stdout.buffer)


if __name__ == "__main__":
    sys.exit(main())
