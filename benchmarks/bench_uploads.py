"""Ordinary uploads end to end, side by side with another checkout (--against): whole requests
to a server of each (`mapqual serve`), medians over rounds that alternate between them.

- estimate tum / estimate bag: POST /runs/{id}/estimates of a long run's own estimate (its
  est.tum, every pose the run's SLAM published) as TUM and as a rosbag1 .bag of
  geometry_msgs/PoseStamped, answered 201: the upload read (in this tree, in the sandbox),
  checked, scored on the run's B, A and SM relations and stored. The run is `--run DIR`
  (DIR/run.db, the SQLite database `mapqual run` stored it in, and its report folder); made
  there when DIR has none (two minutes on an idle machine: odometry SLAM on the virginia_cross
  school with the robot slowed to 0.06 m/s, which ends at its 7,200 s time limit, 72,000
  poses; see SLOW). Each server's first upload is left out (it loads the scorer).
- world upload: POST /worlds?wait=30 of an ordinary floorplan (a 400 x 300 px PNG, new content
  each time), answered 201 (read, analysed, stored).

A checkout without a .venv runs with this Python and PYTHONPATH set to it.

    .venv/bin/python benchmarks/bench_uploads.py --against OTHER_CHECKOUT [--rounds 3]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import shutil
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# a two-hour run: the robot slowed down on a school it cannot finish in two hours, the map
# snapshot rule and the divergence stop pushed out (odometry drifts more than 3 m in two hours)
SLOW = (
    "explore:\n  max_vel_x: 0.06\n  min_vel_x: 0.03\n  time_limit: 7200.0\n"
    "  snapshot_period: 3000.0\n  slam_divergence: 1000.0\n"
)
NO_QUOTAS = {"MAPQUAL_QUOTA_ESTIMATES": "100000000", "MAPQUAL_QUOTA_ESTIMATE_MB": "100000000"}


def python_of(tree: Path) -> tuple[str, dict[str, str]]:
    """(the Python that runs `tree`'s code, the environment it needs)."""
    own = tree / ".venv" / "bin" / "python"
    if own.is_file():
        return str(own), {}
    return sys.executable, {"PYTHONPATH": str(tree)}


def make_run(folder: Path) -> None:
    """A two-hour run stored in folder/run.db, its report in folder/report."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "slow.yaml").write_text(SLOW)
    env = dict(os.environ, DATABASE_URL=f"sqlite:///{folder / 'run.db'}")
    subprocess.run(
        [sys.executable, "-m", "mapqual", "run", "worlds/schools/virginia_cross.yaml", "--slam",
         "odometry", "--params", str(folder / "slow.yaml"), "-o", str(folder / "report")],
        cwd=ROOT, env=env, check=True, stdout=subprocess.DEVNULL,
    )  # fmt: skip


def stored_run(folder: Path) -> tuple[int, Path]:
    """(id, report folder) of the done run in folder/run.db."""
    with contextlib.closing(sqlite3.connect(folder / "run.db")) as db:
        run_id, report = db.execute(
            "SELECT id, report_dir FROM runs WHERE status = 'done' ORDER BY id DESC LIMIT 1"
        ).fetchone()
    return run_id, Path(report)


def bag_of(tum: Path, out: Path) -> Path:
    """The TUM trajectory as a rosbag1 .bag of geometry_msgs/PoseStamped on /slam/pose."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    rows = np.loadtxt(tum, ndmin=2)
    ts = get_typestore(Stores.ROS1_NOETIC)
    T = ts.types
    w = Writer(out)
    w.open()
    conn = w.add_connection("/slam/pose", "geometry_msgs/msg/PoseStamped", typestore=ts)
    for k, (t, x, y, z, qx, qy, qz, qw) in enumerate(rows):
        ns = int(round(t * 1e9))
        msg = T["geometry_msgs/msg/PoseStamped"](
            header=T["std_msgs/msg/Header"](
                seq=k, stamp=T["builtin_interfaces/msg/Time"](sec=ns // 10**9,
                                                             nanosec=ns % 10**9),
                frame_id="map",
            ),
            pose=T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
            ),
        )  # fmt: skip
        w.write(conn, ns, ts.serialize_ros1(msg, conn.msgtype))
    w.close()
    return out


@contextlib.contextmanager
def serve(tree: Path, env: dict[str, str], port: int) -> Iterator[str]:
    """`mapqual serve` of `tree` on `port` with `env`: its base URL once /healthz answers."""
    import httpx

    python, extra = python_of(tree)
    log = open(Path(tempfile.gettempdir()) / "mapqual-bench-uploads.log", "ab")  # noqa: SIM115
    server = subprocess.Popen(
        [python, "-m", "mapqual", "serve", "--port", str(port)], cwd=tree,
        env={**env, **extra}, stdout=log, stderr=log,
    )  # fmt: skip
    base = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                    break
            time.sleep(0.2)
        time.sleep(3)  # its parser processes load meanwhile
        yield base
    finally:
        server.terminate()
        server.wait(30)
        log.close()


def estimate_times(tree: Path, run: Path, files: dict[str, Path], port: int) -> dict[str, float]:
    """Seconds of POST /runs/{id}/estimates of each file (answered 201) on a server of `tree`
    over a copy of the run's database (auth off: every request is the run's owner's)."""
    import httpx

    from tests.services import ensure_redis

    run_id, _ = stored_run(run)
    with tempfile.TemporaryDirectory() as tmp:
        shutil.copy(run / "run.db", Path(tmp) / "run.db")
        env = dict(os.environ, DATABASE_URL=f"sqlite:///{tmp}/run.db", MAPQUAL_AUTH="off",
                   REDIS_URL=ensure_redis(), **NO_QUOTAS)  # fmt: skip
        with serve(tree, env, port) as base:

            def post(kind: str) -> float:
                t0 = time.perf_counter()
                r = httpx.post(
                    f"{base}/api/v1/runs/{run_id}/estimates",
                    files={"file": (files[kind].name, files[kind].read_bytes())},
                    data={"name": f"bench-{kind}"}, timeout=600,
                )  # fmt: skip
                assert r.status_code == 201, r.text
                return time.perf_counter() - t0

            post("tum")  # the first loads the scorer
            return {kind: post(kind) for kind in files}


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
    """Seconds of POST /worlds?wait=30 (answered 201) on a server of `tree` (PostgreSQL)."""
    import httpx

    from tests.services import ensure_redis, scratch_database

    python, extra = python_of(tree)
    with scratch_database("mapqual_bench_up") as db_url:
        env = dict(
            os.environ,
            DATABASE_URL=db_url,
            REDIS_URL=ensure_redis(),
            **extra,
            MAPQUAL_QUOTA_WORLDS="100000000",
            MAPQUAL_QUOTA_UPLOADS_PER_DAY="100000000",
        )
        key = subprocess.run(
            [python, "-m", "mapqual", "users", "add", "bench"], cwd=tree, env=env,
            capture_output=True, text=True, check=True,
        ).stdout.strip().splitlines()[-1]  # fmt: skip
        with serve(tree, env, port) as base:
            hdr = {"Authorization": f"Bearer {key}"}
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", type=Path, required=True, help="another checkout")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--worlds", type=int, default=4, help="world uploads a round")
    ap.add_argument("--run", type=Path, default=Path(tempfile.gettempdir()) / "mapqual-2h-run")
    ap.add_argument("--port", type=int, default=8791)
    args = ap.parse_args()
    trees = {"this": ROOT, "other": args.against.resolve()}
    if not (args.run / "run.db").is_file():
        print(f"making a long run in {args.run} (half an hour)", flush=True)
        make_run(args.run)
    _, report = stored_run(args.run)
    times: dict[str, dict[str, list[float]]] = {name: {} for name in trees}
    with tempfile.TemporaryDirectory() as tmp:
        files = {"tum": report / "est.tum", "bag": bag_of(report / "est.tum", Path(tmp) / "e.bag")}
        n = sum(1 for _ in (report / "est.tum").open())
        print(f"estimate: {n} poses; TUM {files['tum'].stat().st_size / 1e6:.1f} MB, bag "
              f"{files['bag'].stat().st_size / 1e6:.1f} MB", flush=True)  # fmt: skip
        for r in range(args.rounds):  # alternate (and flip the order): drift hits both
            order = list(trees) if r % 2 == 0 else list(reversed(trees))
            for i, name in enumerate(order):
                got = estimate_times(trees[name], args.run, files, args.port + i)
                wt = world_times(trees[name], args.worlds, args.port + i, 1000 * (2 * r + i))
                for what, t in [*((f"estimate {k}", [v]) for k, v in got.items()),
                                ("world upload", wt)]:  # fmt: skip
                    times[name].setdefault(what, []).extend(t)
                print(f"round {r + 1} {name}: " + ", ".join(
                    f"{w} {statistics.median(t):.3f}" for w, t in times[name].items()
                ), flush=True)  # fmt: skip
    print(f"{'':<16}{'this [s]':>10}{'other [s]':>11}{'ratio':>8}")
    for what in times["this"]:
        a, b = (statistics.median(times[name][what]) for name in ("this", "other"))
        print(f"{what:<16}{a:>10.3f}{b:>11.3f}{a / b:>8.2f}")


if __name__ == "__main__":
    main()
