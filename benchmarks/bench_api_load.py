"""bench_api's load: its clients (open and closed loop), its floorplans, the server's CPU time."""

from __future__ import annotations

import asyncio
import gc
import io
import os
import time
from pathlib import Path

import httpx
import numpy as np
from PIL import Image


def png(rooms: tuple[int, int] = (1, 1), room_px: int = 80) -> bytes:
    """rooms[0] x rooms[1] square rooms of room_px pixels joined by 1 m doors (0.05 m/px)."""
    nx, ny = rooms
    img = np.full((ny * room_px + 1, nx * room_px + 1), 255, np.uint8)
    img[::room_px, :] = 0
    img[:, ::room_px] = 0
    door = np.arange(room_px // 2 - 10, room_px // 2 + 10)  # 1 m in the middle of a wall
    for i in range(1, nx):
        for j in range(ny):
            img[j * room_px + door, i * room_px] = 255
    for j in range(1, ny):
        for i in range(nx):
            img[j * room_px, i * room_px + door] = 255
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


async def closed(client, n_requests, n_clients, make_request):
    """n_clients back to back until n_requests are done: (latencies in ms, requests/s)."""
    latencies: list[float] = []
    queue: asyncio.Queue[int] = asyncio.Queue()
    for i in range(n_requests):
        queue.put_nowait(i)

    async def worker():
        while True:
            try:
                i = queue.get_nowait()
            except asyncio.QueueEmpty:
                return
            t0 = time.perf_counter()
            check(await make_request(client, i))
            latencies.append((time.perf_counter() - t0) * 1000)

    t0 = time.perf_counter()
    await asyncio.gather(*(worker() for _ in range(n_clients)))
    return np.array(latencies), n_requests / (time.perf_counter() - t0)


async def open_loop(client, n_requests, n_clients, period, make_request, seed=0):
    """n_clients, each due to send one request every `period` s (random phase): latency in ms
    from the moment each request was due, so a backlog counts (no coordinated omission)."""
    latencies: list[float] = []
    per_client = max(1, n_requests // n_clients)
    phase = np.random.default_rng(seed).uniform(0, period, n_clients)
    start = time.perf_counter() + 0.05

    async def worker(c):
        for k in range(per_client):
            due = start + phase[c] + k * period
            delay = due - time.perf_counter()
            if delay > 0:
                await asyncio.sleep(delay)
            check(await make_request(client, c * per_client + k))
            latencies.append((time.perf_counter() - due) * 1000)

    await asyncio.gather(*(worker(c) for c in range(n_clients)))
    return np.array(latencies)


def check(r) -> None:
    """Raise on an error answer: the figures are of requests that did their work."""
    if r.status_code >= 400:
        raise RuntimeError(f"{r.status_code} {r.text}")


async def measure(base, key, args, make_request):
    """The three figures of one endpoint: sequential, open-loop 50 clients, saturation."""
    # Idle connections are dropped after 1 s, well before uvicorn closes them (after 5 s, its
    # timeout_keep_alive): with httpx's default of 5 s too, a connection the server was closing
    # could be taken for the next request, which failed with httpx.ReadError (nothing in the
    # server's log), mostly when a loaded machine made the server late.
    limits = httpx.Limits(
        max_connections=args.clients, max_keepalive_connections=args.clients, keepalive_expiry=1.0
    )
    # The client's own heap out of its garbage collector's sight: a full collection of it pauses
    # the clients for 50-100 ms, which the open loop would count as server latency.
    gc.collect()
    gc.freeze()
    async with httpx.AsyncClient(
        base_url=base, headers={"Authorization": f"Bearer {key}"}, limits=limits, timeout=30
    ) as client:
        seq, _ = await closed(client, min(args.requests, 300), 1, make_request)
        opn = await open_loop(client, args.requests, args.clients, args.period, make_request)
        _, rate = await closed(client, args.requests, args.clients, make_request)
    return seq, opn, rate


def cpu_s(pid: int) -> float:
    """CPU time [s] (user + system) of a process and its children so far, from /proc."""
    pids = [pid] + [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    ticks = 0
    for p in pids:
        fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        ticks += int(fields[11]) + int(fields[12])
    return ticks / os.sysconf("SC_CLK_TCK")
