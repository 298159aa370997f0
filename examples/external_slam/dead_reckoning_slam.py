#!/usr/bin/env python3
"""An external SLAM program for mapqual, in plain Python (numpy + msgpack): dead reckoning with
a hit/visit map built from the scans, answered as map patches. Speaks mapqual-slam version 1
(docs/external-slam.md) on stdin / stdout; logs go to stderr. Knows nothing of mapqual.

    mapqual run WORLD --slam external --params params.yaml   # params.yaml: see README.md here
"""

from __future__ import annotations

import struct
import sys

import msgpack
import numpy as np

HEADER = struct.Struct(">I")


def read(stream) -> dict | None:
    """The next message, None at the end of the input."""
    header = stream.read(4)
    if len(header) < 4:
        return None
    return msgpack.unpackb(stream.read(HEADER.unpack(header)[0]), raw=False)


def write(stream, message: dict) -> None:
    payload = msgpack.packb(message, use_bin_type=True)
    stream.write(HEADER.pack(len(payload)) + payload)
    stream.flush()


class HitMap:
    """Hits and visits per cell (row 0 = bottom), grown by `margin` when a scan leaves it."""

    def __init__(self, resolution: float, margin: float):
        self.res, self.margin = resolution, margin
        self.origin = np.zeros(2)  # [m] lower-left corner of cell (0, 0)
        self.hits = np.zeros((0, 0), dtype=np.int32)
        self.visits = np.zeros((0, 0), dtype=np.int32)

    def _grow(self, lo: np.ndarray, hi: np.ndarray) -> bool:
        """Make room for the box [lo, hi] [m]; whether the extent changed."""
        h, w = self.hits.shape
        top = self.origin + self.res * np.array([w, h])
        if h and np.all(lo >= self.origin) and np.all(hi < top):
            return False
        new_lo = np.floor((np.minimum(lo, self.origin if h else lo) - self.margin) / self.res)
        new_hi = np.ceil((np.maximum(hi, top if h else hi) + self.margin) / self.res)
        shape = (int(new_hi[1] - new_lo[1]), int(new_hi[0] - new_lo[0]))
        dx, dy = (np.round(self.origin / self.res) - new_lo).astype(int) if h else (0, 0)
        for name in ("hits", "visits"):
            grown = np.zeros(shape, dtype=np.int32)
            grown[dy : dy + h, dx : dx + w] = getattr(self, name)
            setattr(self, name, grown)
        self.origin = new_lo * self.res
        return True

    def add_scan(self, pose, ranges, angles, usable: float, max_range: float):
        """Trace one scan from `pose`; (grew, (col0, row0, col1, row1)) of the cells touched."""
        ok = ranges < max_range
        r = np.minimum(ranges, usable)
        a = pose[2] + angles
        ends = pose[:2] + r[:, None] * np.stack([np.cos(a), np.sin(a)], axis=1)
        grew = self._grow(np.minimum(ends.min(0), pose[:2]), np.maximum(ends.max(0), pose[:2]))
        step = 0.5 * self.res
        s = np.arange(0.0, float(r.max()) + step, step)
        inside = s[None, :] < r[:, None] - step  # samples short of each end point: free
        pts = pose[:2] + (s[None, :, None] * np.stack([np.cos(a), np.sin(a)], 1)[:, None, :])
        free = self._cells(pts[inside])
        hit = self._cells(ends[ok & (ranges <= usable)])
        self.visits.ravel()[np.unique(np.concatenate([free, hit]))] += 1
        self.hits.ravel()[np.unique(hit)] += 1
        ix = ((ends[:, 0] - self.origin[0]) / self.res).astype(int)
        iy = ((ends[:, 1] - self.origin[1]) / self.res).astype(int)
        px, py = (
            int((pose[0] - self.origin[0]) / self.res),
            int((pose[1] - self.origin[1]) / self.res),
        )
        box = (min(ix.min(), px), min(iy.min(), py), max(ix.max(), px) + 1, max(iy.max(), py) + 1)
        return grew, tuple(int(v) for v in box)

    def _cells(self, xy: np.ndarray) -> np.ndarray:
        ij = np.floor((xy - self.origin) / self.res).astype(np.int64)
        return ij[:, 1] * self.hits.shape[1] + ij[:, 0]

    def prob(self, box=None) -> np.ndarray:
        """float32 hits / visits, NaN where never seen (the whole map, or box's cells)."""
        c0, r0, c1, r1 = box if box is not None else (0, 0, self.hits.shape[1], self.hits.shape[0])
        hits, visits = self.hits[r0:r1, c0:c1], self.visits[r0:r1, c0:c1]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(visits > 0, hits / visits, np.nan).astype("<f4")


class DeadReckoning:
    """The pose is the odometry; the map is updated with every scan mapqual sends. The program
    asks mapqual (in its ready) to send only the scans past GMapping's gate, linear_update [m]
    or angular_update [rad] of motion since the last one sent: between them mapqual keeps the
    pose as odometry composed with the last T_map_odom (0 here), as ROS's tf does."""

    def __init__(self, laser: dict, params: dict):
        n = laser["n_beams"]
        self.angles = laser["angle_min"] + laser["angle_increment"] * np.arange(n)
        self.max_range = params.get("max_range") or laser["range_max"] - 0.01
        self.usable = min(params.get("max_urange", 30.0), self.max_range)
        self.gate = {
            "linear_update": params.get("linear_update", 1.0),
            "angular_update": params.get("angular_update", 0.25),
            "temporal_update": params.get("temporal_update", -1.0),
        }
        self.map = HitMap(params.get("delta", 0.05), params.get("map_margin", 8.0))

    def step(self, msg: dict) -> dict:
        pose = np.array(msg["odom"], dtype=float)
        ranges = np.frombuffer(msg["ranges"], dtype="<f8")
        out = {"type": "estimate", "seq": msg["seq"], "pose": list(map(float, pose))}
        out["T_map_odom"] = [0.0, 0.0, 0.0]
        grew, box = self.map.add_scan(pose, ranges, self.angles, self.usable, self.max_range)
        h, w = self.map.hits.shape
        m = {"resolution": self.map.res, "origin": list(map(float, self.map.origin))}
        m.update(width=w, height=h, encoding="float32")
        if grew:  # a new extent: the whole map
            m["data"] = self.map.prob().tobytes()
        else:  # the cells this scan touched
            c0, r0, c1, r1 = box
            patch = {"col": c0, "row": r0, "width": c1 - c0, "height": r1 - r0}
            patch["data"] = self.map.prob(box).tobytes()
            m["patches"] = [patch]
        out.update(updated=True, map=m)
        return out


def main() -> int:
    stdin, stdout = sys.stdin.buffer, sys.stdout.buffer
    slam = None
    while (msg := read(stdin)) is not None:
        kind = msg["type"]
        if kind == "hello":
            if 1 not in msg.get("versions", []):
                write(stdout, {"type": "error", "message": "this program speaks version 1 only"})
                return 1
            write(stdout, {"type": "hello", "protocol": "mapqual-slam", "version": 1,
                           "name": "dead reckoning (example)"})  # fmt: skip
        elif kind == "config":
            slam = DeadReckoning(msg["laser"], msg["params"])
            print(f"dead reckoning: {msg['laser']['n_beams']} beams", file=sys.stderr)
            write(stdout, {"type": "ready", "gate": slam.gate})
        elif kind == "step" and slam is not None:
            write(stdout, slam.step(msg))
        elif kind == "bye":
            break
        else:
            write(stdout, {"type": "error", "message": f"unexpected {kind!r} message"})
    print("dead reckoning: bye", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
