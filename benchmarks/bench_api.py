"""API latency under load: p50/p99 of POST /jobs and GET /jobs/{id} with 50 concurrent clients.

Starts `mapqual serve` (uvicorn, `--server-workers` processes, default one) on loopback against
PostgreSQL (127.0.0.1:5432, a fresh database) and a Redis database of its own, then measures
each endpoint three ways:

- one client, requests back to back: what a request costs the server;
- 50 concurrent clients, each sending one request every `--period` seconds (open loop, from its
  own schedule, so a slow answer delays nobody's next request and waiting time is counted from
  the moment the request was due): the latency users see at that offered load; this is the
  figure the targets apply to (issue 7: p99 < 50 ms for POST /jobs, < 20 ms for GET /jobs/{id});
- 50 clients back to back (closed loop): the saturation throughput, where latency is only
  50 / throughput and says nothing about the server's speed.

Then the queue's throughput: the same job of `--queue-runs` small runs (odometry SLAM, a 3 x 2
room world, `--queue-time-limit` simulated seconds) done by one worker process and then by two
(target, issue 7: two workers >= 1.8x the runs per hour of one). Workers are started and warmed
(numba caches, one run each) before the clock starts. Two rates from the runs' own start and
finish times as the database holds them:
- steady state: runs finished per hour while every worker was busy (from the first finish to
  the last finish before the last run started, when the queue still held work): the
  throughput of the queue, which the target applies to;
- whole job: runs / (last finish - first start), which also counts the tail, when fewer runs
  are left than workers (with n runs over k workers it costs up to one run's time in n / k).

    .venv/bin/python benchmarks/bench_api.py [--requests 2000] [--clients 50] [--period 0.5]
        [--queue-runs 24] [--queue-time-limit 60] [--against OTHER_CHECKOUT [--rounds 3]]

--against DIR measures the two latencies here and in another checkout (a git worktree of the
reference commit with its own .venv), alternately, --rounds times, each on a fresh database,
and prints each round and the median ratio: this machine's speed drifts within the hour, so
only side-by-side figures compare two versions.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import subprocess
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import httpx
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_api_load import check, cpu_s, measure, png  # noqa: E402
from tests.services import ensure_redis, scratch_database  # noqa: E402


def _wait_done(base, hdr, job_id, timeout=1800.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        job = httpx.get(f"{base}/api/v1/jobs/{job_id}", headers=hdr).json()
        if job["status"] in ("done", "failed", "cancelled"):
            if job["status"] != "done":
                raise RuntimeError(f"job {job_id} ended {job['status']}")
            return
        time.sleep(0.2)
    raise TimeoutError(f"job {job_id} not done after {timeout} s")


def _queue_rate(base, hdr, env, n_workers, body_for) -> tuple[float, float]:
    """(steady-state, whole-job) runs per hour of n_workers worker processes (one run at a
    time each); see the module's docstring."""
    mq = [sys.executable, "-m", "mapqual"]
    workers = [
        subprocess.Popen(
            [*mq, "worker", "--concurrency", "1", "--loglevel", "WARNING"],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )
        for _ in range(n_workers)
    ]
    try:
        warm = httpx.post(f"{base}/api/v1/jobs", headers=hdr, json=body_for(n_workers)).json()
        _wait_done(base, hdr, warm["id"])
        job = httpx.post(f"{base}/api/v1/jobs", headers=hdr, json=body_for(None)).json()
        _wait_done(base, hdr, job["id"])
        runs = [httpx.get(f"{base}/api/v1/runs/{r['id']}", headers=hdr).json() for r in job["runs"]]
        return _rates(
            [datetime.fromisoformat(r["started_at"]).timestamp() for r in runs],
            [datetime.fromisoformat(r["finished_at"]).timestamp() for r in runs],
        )
    finally:
        for w in workers:
            os.killpg(w.pid, signal.SIGTERM)
        for w in workers:
            w.wait(timeout=30)


def _rates(starts: list[float], finishes: list[float]) -> tuple[float, float]:
    """(steady-state, whole-job) runs per hour from the runs' start and finish times [s]."""
    f = np.sort(np.asarray(finishes))
    busy = f[f <= max(starts)]  # finished while runs were still waiting to start
    # the slope of the completion count against time, fitted: workers finishing together
    # make a staircase, whose end points alone would bias a (count - 1) / span estimate
    steady = np.polyfit(busy, np.arange(len(busy)), 1)[0] * 3600 if len(busy) >= 3 else np.nan
    return float(steady), len(f) / (f[-1] - min(starts)) * 3600


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=2000)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument(
        "--period", type=float, default=0.5, help="[s] between one client's requests (open loop)"
    )
    ap.add_argument("--port", type=int, default=8765)
    ap.add_argument("--server-workers", type=int, default=1, help="uvicorn worker processes")
    ap.add_argument("--queue-runs", type=int, default=24, help="0 skips the queue figures")
    ap.add_argument("--queue-time-limit", type=float, default=60.0, help="[s] simulated")
    ap.add_argument(
        "--against", type=Path, help="another checkout (with its .venv) to measure side by side"
    )
    ap.add_argument("--rounds", type=int, default=3, help="--against: alternations")
    ap.add_argument(
        "--owners", type=int, default=1, help="users the POSTs go round (default quotas if > 1)"
    )
    args = ap.parse_args()
    if args.against is not None:
        other_py = args.against / ".venv" / "bin" / "python"
        if not (args.against / "backend" / "main.py").is_file() or not other_py.is_file():
            msg = f"bench_api: --against: no checkout with a .venv at {args.against}"
            print(msg, file=sys.stderr)
            raise SystemExit(2)
        _side_by_side(args, args.against.resolve())
        return
    with scratch_database("mapqual_bench") as db_url:
        _bench(args, db_url)


# The benchmark submits thousands of one-run jobs. From one owner that is far past the
# per-owner quotas a service has by default (they answer 429), so with --owners 1 its servers
# run with the quotas out of the way; spread over enough owners (--owners 50: under a hundred
# queued runs each) the default quotas stay in force, as they would in service.
NO_QUOTAS = {
    "MAPQUAL_QUOTA_ACTIVE_RUNS": "100000000",
    "MAPQUAL_QUOTA_SIM_HOURS": "100000000",
    "MAPQUAL_QUOTA_WORLDS": "100000000",
    "MAPQUAL_QUOTA_UPLOADS_PER_DAY": "100000000",
}


SERVER_LOG = Path(tempfile.gettempdir()) / "mapqual-bench-api-server.log"


def _quotas(args) -> dict[str, str]:
    return NO_QUOTAS if args.owners == 1 else {}


def _start(python: str, tree: Path, env: dict, args) -> tuple[subprocess.Popen, str, list[str]]:
    """--owners users and a server of the checkout `tree`: (server process, base URL, keys)."""
    mq = [python, "-m", "mapqual"]
    run = {"env": env, "cwd": tree, "capture_output": True, "text": True, "check": True}
    keys = [subprocess.run([*mq, "users", "add", "bench"], **run).stdout.strip().splitlines()[-1]]
    if args.owners > 1:  # the others in one process (`users add` migrates, so it came first)
        code = (
            "import os\nfrom backend.db.session import session_scope\n"
            "from backend.store import add_user\n"
            "with session_scope(os.environ['DATABASE_URL']) as s:\n"
            f"    for i in range(1, {args.owners}):\n"
            "        print(add_user(s, f'bench{i}')[1])\n"
        )
        keys += subprocess.run([python, "-c", code], **run).stdout.split()
    log = open(SERVER_LOG, "ab")  # noqa: SIM115 - the server's; closed with this process
    server = subprocess.Popen(
        [*mq, "serve", "--port", str(args.port), "--workers", str(args.server_workers)],
        env=env,
        cwd=tree,
        stdout=log,
        stderr=log,
    )
    base = f"http://127.0.0.1:{args.port}"
    for _ in range(150):
        try:
            if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                break
        except httpx.HTTPError:
            time.sleep(0.2)
    return server, base, keys


def _upload(base: str, hdr: dict, name: str, png: bytes) -> dict:
    """Upload a plan and wait for its analysis (`wait`; a server that has no such parameter
    analyses in the request and ignores it)."""
    r = httpx.post(
        f"{base}/api/v1/worlds",
        headers=hdr,
        params={"wait": 30},
        files={"file": (name, png)},
        data={"resolution": "0.05"},
        timeout=60,
    )
    check(r)
    return r.json()


def _latencies(base: str, keys: list[str], args, pid: int | None = None) -> dict[str, tuple]:
    """POST /jobs and GET /jobs/{id}: (sequential, open loop, saturation rate, server CPU ms
    per request) of each. The POSTs go round the owners, each on a world of its own; the GETs
    read the first owner's. CPU time drifts with the machine less than latency does."""
    auth = [{"Authorization": f"Bearer {key}"} for key in keys]
    # 10 simulated minutes a run: 86 queued runs an owner (4,300 POSTs over 50 owners) ask for
    # 14 h, within the default quota of 100 simulated hours
    params = {"explore": {"time_limit": 600.0}}
    bodies = [
        {"world_id": _upload(base, hdr, "b.png", png())["id"], "runs": 1, "slam": "odometry",
         "params": params}
        for hdr in auth
    ]  # fmt: skip

    async def post_job(client, i):
        k = i % len(keys)
        return await client.post("/api/v1/jobs", json=bodies[k], headers=auth[k])

    # warm-up, outside the CPU count: one POST per owner and a GET, so what a server does once
    # on its first requests (e.g. importing the pipeline's parameters) is not spread over them
    for body, hdr in zip(bodies, auth, strict=True):
        job = httpx.post(f"{base}/api/v1/jobs", json=body, headers=hdr, timeout=60)
        check(job)
    check(httpx.get(f"{base}/api/v1/jobs/{job.json()['id']}", headers=hdr))
    n_requests = min(args.requests, 300) + 2 * args.requests  # what _measure sends
    c0 = cpu_s(pid) if pid else 0.0
    post = asyncio.run(measure(base, keys[0], args, post_job))
    c1 = cpu_s(pid) if pid else 0.0
    page = httpx.get(f"{base}/api/v1/jobs", headers=auth[0], params={"limit": 200}).json()
    job_ids = [j["id"] for j in page["items"]]

    async def get_job(client, i):
        return await client.get(f"/api/v1/jobs/{job_ids[i % len(job_ids)]}")

    get = asyncio.run(measure(base, keys[0], args, get_job))
    c2 = cpu_s(pid) if pid else 0.0
    per = 1000.0 / n_requests
    return {
        "POST /jobs": (*post, (c1 - c0) * per),
        "GET /jobs/{id}": (*get, (c2 - c1) * per),
    }


def _side_by_side(args, other: Path) -> None:
    """Open-loop p50/p99 of both endpoints here and in `other`, alternately, --rounds times,
    each on a fresh database; the median ratio (this / other) of each figure."""
    import redis

    redis_url = ensure_redis().rsplit("/", 1)[0] + "/12"
    trees = {"this": (sys.executable, ROOT), "other": (str(other / ".venv/bin/python"), other)}
    figures: dict[str, dict[str, list[float]]] = {name: {} for name in trees}
    print(f"side by side: this = {ROOT}, other = {other}; {args.rounds} rounds")
    for r in range(args.rounds):
        # which tree goes first alternates too: the machine's drift within a round then
        # favours neither
        for name, (python, tree) in sorted(trees.items(), reverse=r % 2 == 1):
            with scratch_database("mapqual_bench") as db_url:
                env = dict(os.environ, DATABASE_URL=db_url, REDIS_URL=redis_url, **_quotas(args))
                redis.Redis.from_url(redis_url).flushdb()
                server, base, keys = _start(python, tree, env, args)
                try:
                    got = _latencies(base, keys, args, server.pid)
                finally:
                    server.terminate()
                    server.wait(timeout=10)
                    redis.Redis.from_url(redis_url).flushdb()
            line = []
            for label, (_, opn, _, cpu) in got.items():
                p50, p99 = np.percentile(opn, [50, 99])
                figures[name].setdefault(f"{label} p50", []).append(float(p50))
                figures[name].setdefault(f"{label} p99", []).append(float(p99))
                figures[name].setdefault(f"{label} CPU/req", []).append(float(cpu))
                line.append(f"{label} p50 {p50:5.1f} p99 {p99:5.1f} ms, CPU {cpu:4.2f} ms/req")
            print(f"  round {r + 1} {name:5s}: " + "; ".join(line), flush=True)
    print(
        f"{args.clients} clients every {args.period:g} s (open loop), {args.owners} owner(s); "
        "median over rounds, "
        f"ratio this / other (below 1: this is faster); load average "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}"
    )
    for fig in figures["this"]:
        a, b = figures["this"][fig], figures["other"][fig]
        ratios = [x / y for x, y in zip(a, b, strict=True)]
        print(
            f"  {fig:22s} this {np.median(a):6.1f} ms  other {np.median(b):6.1f} ms  "
            f"ratio {np.median(ratios):.2f} (rounds {', '.join(f'{x:.2f}' for x in ratios)})"
        )


def _bench(args, db_url: str) -> None:
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/12"
    env = dict(os.environ, DATABASE_URL=db_url, REDIS_URL=redis_url, **_quotas(args))
    server, base, keys = _start(sys.executable, ROOT, env, args)
    try:
        hdr = {"Authorization": f"Bearer {keys[0]}"}
        got = _latencies(base, keys, args, server.pid)
        offered = args.clients / args.period
        print(
            f"PostgreSQL + Redis on loopback, {args.server_workers} uvicorn process(es), "
            f"{args.owners} owner(s), "
            f"{args.clients} clients every {args.period:g} s; load average "
            f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}"
        )
        for (label, (seq, opn, rate, cpu)), target in zip(got.items(), (50, 20), strict=True):
            s50, s99 = np.percentile(seq, [50, 99])
            o50, o99 = np.percentile(opn, [50, 99])
            verdict = "ok" if o99 < target else "MISSED"
            print(f"{label}")
            print(f"  1 client back to back       p50 {s50:6.1f} ms  p99 {s99:6.1f} ms")
            print(
                f"  {args.clients} clients, {offered:.0f} req/s     p50 {o50:6.1f} ms  "
                f"p99 {o99:6.1f} ms  (target p99 < {target} ms: {verdict})"
            )
            print(f"  {args.clients} clients back to back saturate at {rate:6.0f} req/s")
            print(f"  server CPU {cpu:.2f} ms per request (all three phases)")
        if args.queue_runs:
            import redis

            redis.Redis.from_url(redis_url).flushdb()  # the latency phase's runs stay unrun
            rooms = _upload(base, hdr, "rooms.png", png((3, 2), 120))

            def body_for(n):
                return {
                    "world_id": rooms["id"],
                    "seeds": list(range(1000, 1000 + n)) if n else list(range(args.queue_runs)),
                    "slam": "odometry",
                    "params": {"explore": {"time_limit": args.queue_time_limit}},
                }

            one = _queue_rate(base, hdr, env, 1, body_for)
            two = _queue_rate(base, hdr, env, 2, body_for)
            verdict = "ok" if two[0] >= 1.8 * one[0] else "MISSED"
            print(
                f"queue: {args.queue_runs} runs of {args.queue_time_limit:.0f} s simulated; "
                f"steady state: 1 worker {one[0]:6.0f} runs/h, 2 workers {two[0]:6.0f} runs/h, "
                f"ratio {two[0] / one[0]:.2f} (target >= 1.8: {verdict}); whole job with its "
                f"tail: {one[1]:6.0f} and {two[1]:6.0f} runs/h, ratio {two[1] / one[1]:.2f}; "
                f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}"
            )
    finally:
        server.terminate()
        server.wait(timeout=10)
        import redis

        redis.Redis.from_url(redis_url).flushdb()


if __name__ == "__main__":
    main()
