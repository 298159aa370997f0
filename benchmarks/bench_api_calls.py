"""Python function calls per API request, side by side: a figure the machine's drift cannot blur.

Latency and CPU time on this machine drift by a third within an hour and swing with whatever
else runs, so a 5 % change of the API's cost hides in their noise. The number of Python function
calls a request makes does not drift: for the same code, data and packages it is the same in
every run. This script counts them (cProfile, the thread pool's share included) for
`GET /jobs/{id}` and `POST /jobs`, in this checkout and, with `--against`, in another one:

    .venv/bin/python benchmarks/bench_api_calls.py [--requests 1000] [--against OTHER_CHECKOUT]

Each checkout gets a fresh PostgreSQL database, set up through its own server (`mapqual serve`:
a user, a world, 20 jobs of 3 runs), then its app is called in process through
`httpx.ASGITransport`, so uvicorn's HTTP parsing is not counted (it is the same code in both).
C code (psycopg, pydantic-core, the JSON encoder) is not counted: the figure shows what Python
code a change added or removed, not the whole of a request's cost.
"""

from __future__ import annotations

import argparse
import asyncio
import cProfile
import json
import os
import pstats
import subprocess
import sys
import threading
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
JOBS = 20


def _setup(tree: Path, db_url: str, redis_url: str, port: int) -> dict:
    """A user, a world and JOBS jobs in `db_url`, made by `tree`'s own server."""
    sys.path.insert(0, str(ROOT))
    import httpx

    from benchmarks import bench_api as B

    class Args:
        owners, server_workers = 1, 1

    Args.port = port
    env = dict(os.environ, DATABASE_URL=db_url, REDIS_URL=redis_url, **B.NO_QUOTAS)
    server, base, keys = B._start(str(tree / ".venv/bin/python"), tree, env, Args)
    try:
        hdr = {"Authorization": f"Bearer {keys[0]}"}
        world = B._upload(base, hdr, "b.png", B.png())
        body = {"world_id": world["id"], "runs": 3, "slam": "odometry",
                "params": {"explore": {"time_limit": 600.0}}}  # fmt: skip
        ids = [
            httpx.post(f"{base}/api/v1/jobs", json=body, headers=hdr, timeout=60).json()["id"]
            for _ in range(JOBS)
        ]
        return {"key": keys[0], "ids": ids, "body": body}
    finally:
        server.terminate()
        server.wait(timeout=10)


def _count(n: int, setup: dict) -> dict[str, float]:
    """In the checkout's own interpreter (cwd): Python calls per request of each route."""
    import httpx

    import backend.api.routes.jobs as routes
    from backend.core.config import Settings

    try:
        from mapqual.app import create_app
    except ImportError:  # a checkout from before the app moved above backend and frontend
        from backend.main import create_app

    app = create_app(Settings())
    # the thread pool's work: a profiler per (worker thread, route); `on` names the route
    profiles: dict[tuple[int, str], cProfile.Profile] = {}
    on: list[str | None] = [None]
    in_session = routes.in_session

    def profiled(*args):
        if on[0] is None:
            return in_session(*args)
        p = profiles.setdefault((threading.get_ident(), on[0]), cProfile.Profile())
        p.enable()
        try:
            return in_session(*args)
        finally:
            p.disable()

    routes.in_session = profiled
    hdr = {"Authorization": f"Bearer {setup['key']}"}

    async def send(k: int, route: str) -> None:
        transport = httpx.ASGITransport(app=app)
        async with httpx.AsyncClient(transport=transport, base_url="http://t", headers=hdr) as c:
            for i in range(k):
                if route == "GET /jobs/{id}":
                    r = await c.get(f"/api/v1/jobs/{setup['ids'][i % JOBS]}")
                else:
                    r = await c.post("/api/v1/jobs", json={**setup["body"], "runs": 1})
                if r.status_code >= 300:
                    raise SystemExit(f"{route}: {r.status_code} {r.text[:200]}")

    out = {}
    for route in ("GET /jobs/{id}", "POST /jobs"):
        asyncio.run(send(50, route))  # warm: first-request imports and caches stay out
        main = cProfile.Profile()
        on[0] = route
        main.enable()
        asyncio.run(send(n, route))
        main.disable()
        on[0] = None
        stats = pstats.Stats(main)
        for (_, of_route), p in profiles.items():
            if of_route == route:
                stats.add(p)
        out[route] = stats.total_calls / n
    return out


def _measure(tree: Path, n: int, port: int) -> dict[str, float]:
    sys.path.insert(0, str(ROOT))
    from benchmarks.bench_api import NO_QUOTAS
    from tests.services import ensure_redis, scratch_database

    redis_url = ensure_redis().rsplit("/", 1)[0] + "/12"
    with scratch_database("mapqual_calls") as db_url:
        setup = _setup(tree, db_url, redis_url, port)
        env = dict(os.environ, DATABASE_URL=db_url, REDIS_URL=redis_url, **NO_QUOTAS)
        child = subprocess.run(
            [str(tree / ".venv/bin/python"), __file__, "--child", str(n), json.dumps(setup)],
            cwd=tree, env=env, capture_output=True, text=True, check=False,
        )  # fmt: skip
        if child.returncode != 0:
            raise SystemExit(f"bench_api_calls: {tree}: {child.stderr.strip()[-400:]}")
        return json.loads(child.stdout.splitlines()[-1])


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":  # inside a checkout's interpreter
        sys.path.insert(0, os.getcwd())
        print(json.dumps(_count(int(sys.argv[2]), json.loads(sys.argv[3]))))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=1000)
    ap.add_argument("--port", type=int, default=8775)
    ap.add_argument("--against", type=Path, help="another checkout (with its .venv)")
    args = ap.parse_args()
    trees = {"this": ROOT}
    if args.against is not None:
        if not (args.against / ".venv/bin/python").is_file():
            print(f"bench_api_calls: --against: no checkout with a .venv at {args.against}",
                  file=sys.stderr)  # fmt: skip
            raise SystemExit(2)
        trees["other"] = args.against.resolve()
    got = {name: _measure(tree, args.requests, args.port) for name, tree in trees.items()}
    print(f"Python calls per request ({args.requests} requests of each route)")
    for route, calls in got["this"].items():
        line = f"  {route:16s} this {calls:7.0f}"
        if "other" in got:
            other = got["other"][route]
            line += f"  other {other:7.0f}  ratio {calls / other:.3f}"
        print(line)
    for name, tree in trees.items():
        print(f"  {name} = {tree}")


if __name__ == "__main__":
    main()
