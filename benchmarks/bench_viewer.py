"""What the live feed costs a run: `run_one` without a progress callback, with the worker's
ProgressReporter publishing to Redis while nobody listens, and while a viewer listens (a
separate process that folds every message into the viewer's LiveRun, as `mapqual viewer`
does).

Targets (issue 8): nobody watching <= 2 % slower, a viewer attached <= 10 % slower.

    .venv/bin/python benchmarks/bench_viewer.py [--world worlds/bormann/office_a.yaml]
        [--slam rbpf] [--time-limit 120] [--repeats 3] [--database postgresql|sqlite]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from worker.slam import registry  # noqa: E402


def listen(redis_url: str, run_id: int) -> None:
    """The viewer's side: subscribe and fold every message in; prints counts on SIGTERM."""
    import signal

    import redis

    from frontend.live import LiveRun
    from worker.live_wire import channel

    live, n, nbytes = LiveRun(run_id), 0, 0
    sub = redis.Redis.from_url(redis_url).pubsub(ignore_subscribe_messages=True)
    sub.subscribe(channel(run_id))
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    print("ready", flush=True)
    while not stop:
        msg = sub.get_message(timeout=0.2)
        if msg is not None:
            live.apply(json.loads(msg["data"]))
            n, nbytes = n + 1, nbytes + len(msg["data"])
    out = {"messages": n, "bytes": nbytes, "path_points": len(live.gt)}
    print(json.dumps({**out, "cpu_s": time.process_time()}), flush=True)


def _stored_run(url: str, world) -> int:
    from backend.db.migrate import upgrade
    from backend.db.session import session_scope
    from backend.store import add_user, create_job, mark_run_started, save_world

    upgrade(url)
    with session_scope(url) as s:
        uid = add_user(s, "bench")[0].id
        w = save_world(s, owner_id=uid, world=world, sha256="bench", source_format="yaml")
        run_id = create_job(s, owner_id=uid, world_id=w.id, slam="rbpf", params={}, seeds=[1])
        run_id = run_id.runs[0].id
        mark_run_started(s, run_id)
    return run_id


class Clocked:
    """A progress callback with the wall time spent inside it counted: the publisher's direct
    cost to the run, which the machine's load blurs far less than whole-run timings."""

    def __init__(self, inner):
        self.inner = inner
        self.inside_s = 0.0  # [s] wall
        self.inside_cpu_s = 0.0  # [s] CPU of this process

    def __call__(self, p) -> None:
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            self.inner(p)
        finally:
            self.inside_s += time.perf_counter() - t0
            self.inside_cpu_s += time.process_time() - c0


def _timed(world, params, seed, reporter) -> tuple[tuple[float, ...], dict]:
    """((wall, CPU, shares of the wall and of the CPU inside the callback) of one run, its
    summary)."""
    from worker.pipeline import run_one

    clocked = Clocked(reporter) if reporter is not None else None
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_one(world, params, seed, clocked)
    wall = time.perf_counter() - t0
    cpu = time.process_time() - c0
    shares = (clocked.inside_s / wall, clocked.inside_cpu_s / cpu) if clocked else (0.0, 0.0)
    return (wall, cpu, *shares), result.summary


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default=str(ROOT / "worlds/bormann/office_a.yaml"))
    ap.add_argument("--slam", default="rbpf", choices=registry.names())
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=120.0, help="[s] simulated")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--redis", default="own",
        help="a Redis URL, or 'own': a private redis-server (pub/sub channels are server-wide)",
    )  # fmt: skip
    ap.add_argument(
        "--database", default="postgresql", choices=["postgresql", "sqlite"],
        help="where the publisher stores progress (a throwaway database on 127.0.0.1:5432)",
    )  # fmt: skip
    ap.add_argument("--listen", nargs=2, metavar=("REDIS_URL", "RUN_ID"), help=argparse.SUPPRESS)
    return ap.parse_args()


def main() -> None:
    args = _args()
    if args.listen:
        listen(args.listen[0], int(args.listen[1]))
        return

    import redis

    from backend.services.progress import ProgressReporter
    from worker.pipeline import run_one
    from worker.run_params import RunParams
    from worker.world.loader import load_world

    world = load_world(args.world)
    data = {"algorithm": args.slam, "explore": {"time_limit": args.time_limit}}
    params = RunParams.from_json(data)
    run_one(world, RunParams.from_json({**data, "explore": {"time_limit": 5.0}}), args.seed)
    inf = (float("inf"),) * 4
    # (wall [s], CPU [s], shares of wall and CPU inside the callback), each the best of repeats
    best = {"none": inf, "noop": inf, "unwatched": inf, "watched": inf}
    with (
        tempfile.TemporaryDirectory() as tmp,
        _database(args.database, tmp) as url,
        _redis_server(args.redis) as redis_url,
    ):
        client = redis.Redis.from_url(redis_url)
        run_id = _stored_run(url, world)
        for rep in range(args.repeats):
            took, ref = _timed(world, params, args.seed, None)
            best["none"] = _best(best["none"], took)
            took, _ = _timed(world, params, args.seed, lambda p: None)
            best["noop"] = _best(best["noop"], took)
            reporter = ProgressReporter(url, run_id, client)
            took, summary = _timed(world, params, args.seed, reporter)
            assert summary.timings.sim_time_s == ref.timings.sim_time_s
            best["unwatched"] = _best(best["unwatched"], took)
            assert reporter._listeners == 0
            took, stats = _watched(redis_url, url, run_id, client, world, params, args.seed)
            best["watched"] = _best(best["watched"], took)
            print(f"repeat {rep + 1}, best (wall, CPU, inside wall, CPU): {best}", flush=True)
    _report(world.name, args, best, stats, ref.timings.sim_time_s)


def _report(name: str, args: argparse.Namespace, best: dict, stats: dict, sim_t: float) -> None:
    """The figures: each way of running against the run without a progress callback."""
    load = ", ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"{name}, {args.slam}, seed {args.seed}: {sim_t:.0f} s simulated, best of "
          f"{args.repeats}, progress stored in {args.database}; load average {load}")  # fmt: skip
    w0, c0, _, _ = best["none"]
    print("changes against the run without a callback; 'inside': shares of the run's wall and")
    print("CPU time spent in the callback (the direct cost, which load blurs far less)")
    print(f"no progress callback:   wall {w0:7.2f} s          CPU {c0:7.2f} s")
    for key, target in (("noop", None), ("unwatched", 2.0), ("watched", 10.0)):
        w, c, in_w, in_c = best[key]
        dw, dc = 100 * (w / w0 - 1), 100 * (c / c0 - 1)
        goal = "(the loop's own progress work)" if target is None else f"(target <= {target:g} %)"
        print(f"{_LABELS[key]}: wall {w:6.2f} s {dw:+5.1f} %  CPU {c:6.2f} s {dc:+5.1f} %  "
              f"inside {100 * in_w:4.2f} % wall, {100 * in_c:4.2f} % CPU  {goal}")  # fmt: skip
    rate = stats["bytes"] / best["watched"][0] / 1e3
    print(f"the viewer received {stats['messages']} messages, {stats['bytes'] / 1e3:.0f} kB "
          f"({rate:.1f} kB/s), {stats['path_points']} path points; it used "
          f"{stats['cpu_s']:.2f} s CPU")  # fmt: skip


@contextmanager
def _database(kind: str, tmp: str) -> Iterator[str]:
    """A throwaway database URL: a SQLite file, or a PostgreSQL database dropped afterwards."""
    if kind == "sqlite":
        yield f"sqlite:///{tmp}/bench.db"
        return
    from tests.services import scratch_database

    with scratch_database("mapqual_bench") as url:
        yield url


@contextmanager
def _redis_server(url: str) -> Iterator[str]:
    """`url`, or the URL of a private redis-server on a free port, stopped afterwards."""
    if url != "own":
        yield url
        return
    import socket

    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    proc = subprocess.Popen(
        ["redis-server", "--bind", "127.0.0.1", "--port", str(port), "--save", "",
         "--appendonly", "no"],
        stdout=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        for _ in range(100):
            try:
                socket.create_connection(("127.0.0.1", port), timeout=0.2).close()
                break
            except OSError:
                time.sleep(0.05)
        yield f"redis://127.0.0.1:{port}/0"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


_LABELS = {
    "noop": "a no-op callback     ",
    "unwatched": "publisher, unwatched ",
    "watched": "publisher, watched   ",
}


def _best(a: tuple, b: tuple) -> tuple:
    return tuple(min(x, y) for x, y in zip(a, b, strict=True))


def _watched(redis_url, url, run_id, client, world, params, seed) -> tuple[tuple, dict]:
    """One run with a listening viewer process."""
    from backend.services.progress import ProgressReporter

    proc = subprocess.Popen(
        [sys.executable, __file__, "--listen", redis_url, str(run_id)],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert proc.stdout.readline().strip() == "ready"
    try:
        took, _ = _timed(world, params, seed, ProgressReporter(url, run_id, client))
    finally:
        time.sleep(0.5)
        proc.terminate()
        out = proc.communicate(timeout=10)[0]
    return took, json.loads(out.strip().splitlines()[-1])


if __name__ == "__main__":
    main()
