"""What reading uploads in the sandbox costs, side by side with another checkout (--against).

Two figures, each a median over --rounds rounds that alternate between the checkouts:

- estimates: the parse step of POST /runs/{id}/estimates on a two-hour estimate at 10 Hz
  (72,000 poses) as TUM and as a rosbag1 .bag of PoseStamped, run by each checkout's own
  code in a process of its own: in a checkout with `backend.sandbox`, the route's
  `read_estimate_sandboxed` (a forked, limited parser, the pool warmed first); otherwise
  the route's former in-process `read_estimate`. Scoring, the same code in both, is left
  out: it only adds the same seconds to both sides.
- worlds: POST /worlds?wait=30 of an ordinary floorplan (a 400 x 300 px PNG, new content
  each time) to a server of each checkout (`mapqual serve`, PostgreSQL, Redis), answered 201.

    .venv/bin/python benchmarks/bench_uploads.py --against OTHER_CHECKOUT [--rounds 7]
"""

from __future__ import annotations

import argparse
import io
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

POSES = 72_000  # two hours at 10 Hz

PARSE = r"""
import json, sys, time
from pathlib import Path
path, rounds = Path(sys.argv[1]), int(sys.argv[2])
data = path.read_bytes()
try:
    from backend.api.routes.bags import read_estimate_sandboxed
    from backend.core.config import Settings
    from backend.sandbox import Sandbox
    box = Sandbox(Settings())
    read = lambda: read_estimate_sandboxed(box, path.name, data, None)
    read()  # the pool's processes load their parsers once, at the API's start
except ImportError:
    import tempfile
    from backend.api.routes.bags import _estimate_file
    from worker.export.estimate import read_estimate
    def read():
        with tempfile.TemporaryDirectory() as tmp:
            return read_estimate(_estimate_file(path.name, data, Path(tmp)), "auto", None)
    read()
times = []
for _ in range(rounds):
    t0 = time.perf_counter(); est = read(); times.append(time.perf_counter() - t0)
    assert len(est.t) == 72000, len(est.t)
print(json.dumps(times))
"""


def make_estimates(folder: Path) -> dict[str, Path]:
    """A two-hour estimate as TUM and as a rosbag1 bag of geometry_msgs/PoseStamped."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    t = np.arange(POSES) * 0.1
    x, y, yaw = np.cos(t / 100) * 5, np.sin(t / 100) * 5, (t / 100 + np.pi / 2) % (2 * np.pi)
    tum = folder / "est.tum"
    with tum.open("w") as f:
        for k in range(POSES):
            qz, qw = np.sin(yaw[k] / 2), np.cos(yaw[k] / 2)
            f.write(f"{t[k]:.3f} {x[k]:.6f} {y[k]:.6f} 0 0 0 {qz:.9f} {qw:.9f}\n")
    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    bag = folder / "est.bag"
    w = Writer(bag)
    w.open()
    conn = w.add_connection("/slam/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
    for k in range(POSES):
        sec, nsec = int(t[k]), int(round((t[k] % 1) * 1e9))
        msg = T["geometry_msgs/msg/PoseStamped"](
            header=T["std_msgs/msg/Header"](
                seq=k, stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="map"
            ),
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=x[k], y=y[k], z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=np.sin(yaw[k] / 2), w=np.cos(yaw[k] / 2)
                ),
            ),
        )
        w.write(conn, sec * 10**9 + nsec, ts.serialize_ros1(msg, conn.msgtype))
    w.close()
    return {"tum": tum, "bag": bag}


def parse_times(tree: Path, path: Path, rounds: int) -> list[float]:
    """Seconds of each round of the estimate's parse step in `tree`'s code."""
    out = subprocess.run(
        [str(tree / ".venv/bin/python"), "-c", PARSE, str(path), str(rounds)],
        cwd=tree, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


def floorplan(k: int) -> bytes:
    from PIL import Image

    img = np.full((300, 400), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:150, 200] = 0
    img[5, 5 + k % 300] = 0  # new content every time (an upload of the same is not analysed)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def world_times(tree: Path, rounds: int, port: int, start: int) -> list[float]:
    """Seconds of POST /worlds?wait=30 (answered 201) on a server of `tree`."""
    import httpx

    from benchmarks import bench_api as B
    from tests.services import ensure_redis, scratch_database

    class Args:
        owners, server_workers = 1, 1

    Args.port = port
    with scratch_database("mapqual_bench_up") as db_url:
        env = dict(os.environ, DATABASE_URL=db_url, REDIS_URL=ensure_redis(), **B.NO_QUOTAS)
        server, base, keys = B._start(str(tree / ".venv/bin/python"), tree, env, Args)
        try:
            hdr = {"Authorization": f"Bearer {keys[0]}"}
            times = []
            for k in range(start, start + rounds + 1):
                t0 = time.perf_counter()
                r = httpx.post(
                    f"{base}/api/v1/worlds", headers=hdr, params={"wait": 30},
                    files={"file": (f"w{k}.png", floorplan(k), "image/png")},
                    data={"resolution": "0.05"}, timeout=60,
                )  # fmt: skip
                assert r.status_code == 201, r.text
                times.append(time.perf_counter() - t0)
            return times[1:]  # the first warms the server (its pools start on first use)
        finally:
            server.terminate()
            server.wait(30)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", type=Path, required=True, help="another checkout (with .venv)")
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--port", type=int, default=8791)
    args = ap.parse_args()
    trees = {"this": ROOT, "other": args.against.resolve()}
    med: dict[str, dict[str, float]] = {name: {} for name in trees}
    with tempfile.TemporaryDirectory() as tmp:
        files = make_estimates(Path(tmp))
        for kind, path in files.items():
            runs: dict[str, list[float]] = {name: [] for name in trees}
            for _ in range(args.rounds):  # alternate: drift of the machine hits both
                for name, tree in trees.items():
                    runs[name] += parse_times(tree, path, 1)
            for name in trees:
                med[name][f"estimate {kind}"] = statistics.median(runs[name])
    wt: dict[str, list[float]] = {name: [] for name in trees}
    for r in range(3):
        for i, (name, tree) in enumerate(trees.items()):
            start = 1000 * (r * 2 + i)
            wt[name] += world_times(tree, max(1, args.rounds // 3), args.port + i, start)
    for name in trees:
        med[name]["world upload"] = statistics.median(wt[name])
    print(f"{'':<22}{'this [s]':>10}{'other [s]':>11}{'ratio':>8}")
    for what in med["this"]:
        a, b = med["this"][what], med["other"][what]
        print(f"{what:<22}{a:>10.3f}{b:>11.3f}{a / b:>8.2f}")


if __name__ == "__main__":
    main()
