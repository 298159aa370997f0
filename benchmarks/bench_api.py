"""API latency under load: p50/p99 of POST /jobs and GET /jobs/{id} with 50 concurrent clients.

Starts `mapqual serve` (uvicorn) on loopback against PostgreSQL (127.0.0.1:5432, a fresh
database) and a Redis database of its own, then drives it with 50 concurrent httpx clients.
Targets (issue 7): p99 < 50 ms for POST /jobs, < 20 ms for GET /jobs/{id}.

    .venv/bin/python benchmarks/bench_api.py [--requests 2000] [--clients 50]
"""

from __future__ import annotations

import argparse
import asyncio
import io
import os
import subprocess
import sys
import time
import uuid
from pathlib import Path

import httpx
import numpy as np
from PIL import Image
from sqlalchemy import create_engine, text

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.services import ensure_postgres, ensure_redis  # noqa: E402


def _png() -> bytes:
    img = np.full((60, 80), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


async def _drive(base, key, n_requests, n_clients, make_request):
    """Run n_requests through n_clients concurrent workers; latencies in ms."""
    latencies: list[float] = []
    queue: asyncio.Queue[int] = asyncio.Queue()
    for i in range(n_requests):
        queue.put_nowait(i)
    limits = httpx.Limits(max_connections=n_clients, max_keepalive_connections=n_clients)
    async with httpx.AsyncClient(
        base_url=base, headers={"Authorization": f"Bearer {key}"}, limits=limits, timeout=30
    ) as client:

        async def worker():
            while True:
                try:
                    i = queue.get_nowait()
                except asyncio.QueueEmpty:
                    return
                t0 = time.perf_counter()
                r = await make_request(client, i)
                latencies.append((time.perf_counter() - t0) * 1000)
                if r.status_code >= 400:
                    raise RuntimeError(f"{r.status_code} {r.text}")

        await asyncio.gather(*(worker() for _ in range(n_clients)))
    return np.array(latencies)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=2000)
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--port", type=int, default=8765)
    args = ap.parse_args()

    admin_url = ensure_postgres()
    name = f"mapqual_bench_{uuid.uuid4().hex[:8]}"
    admin = create_engine(admin_url, isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f'CREATE DATABASE "{name}"'))
    db_url = admin_url.rsplit("/", 1)[0] + f"/{name}"
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/12"
    env = dict(os.environ, DATABASE_URL=db_url, REDIS_URL=redis_url)
    mq = [sys.executable, "-m", "mapqual"]
    key = (
        subprocess.run(
            [*mq, "users", "add", "bench"], env=env, capture_output=True, text=True, check=True
        )
        .stdout.strip()
        .splitlines()[-1]
    )
    server = subprocess.Popen(
        [*mq, "serve", "--port", str(args.port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    base = f"http://127.0.0.1:{args.port}"
    try:
        for _ in range(100):
            try:
                if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.2)
        hdr = {"Authorization": f"Bearer {key}"}
        world = httpx.post(
            f"{base}/api/v1/worlds",
            headers=hdr,
            files={"file": ("b.png", _png())},
            data={"resolution": "0.05"},
        ).json()
        body = {"world_id": world["id"], "runs": 1, "slam": "odometry"}

        async def post_job(client, i):
            return await client.post("/api/v1/jobs", json=body)

        post = asyncio.run(_drive(base, key, args.requests, args.clients, post_job))
        job_ids = [
            j["id"]
            for j in httpx.get(f"{base}/api/v1/jobs", headers=hdr, params={"limit": 200}).json()[
                "items"
            ]
        ]

        async def get_job(client, i):
            return await client.get(f"/api/v1/jobs/{job_ids[i % len(job_ids)]}")

        get = asyncio.run(_drive(base, key, args.requests, args.clients, get_job))
        print(
            f"{args.clients} concurrent clients, {args.requests} requests each kind, "
            "PostgreSQL + Redis on loopback, 1 uvicorn worker"
        )
        for label, lat, target in (("POST /jobs", post, 50), ("GET /jobs/{id}", get, 20)):
            p50, p99 = np.percentile(lat, [50, 99])
            verdict = "ok" if p99 < target else "MISSED"
            print(
                f"{label:16s} p50 {p50:7.1f} ms   p99 {p99:7.1f} ms   "
                f"(target p99 < {target} ms: {verdict})"
            )
    finally:
        server.terminate()
        server.wait(timeout=10)
        import redis

        redis.Redis.from_url(redis_url).flushdb()
        with admin.connect() as c:
            c.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))


if __name__ == "__main__":
    main()
