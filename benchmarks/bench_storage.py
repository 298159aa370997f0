"""Issue 50's speed figures: (1) two S3 clients side by side (boto3, minio) on one endpoint,
(2) a report.zip the size of a two-hour run streamed from storage through the storage layer
(MB/s, and how much the process's memory grows), (3) a whole `mapqual run` with S3 storage
against the local folder, and against another checkout (--against, local folder).

The S3 endpoint is moto's server started here on loopback unless AWS_ENDPOINT_URL is set.
    python benchmarks/bench_storage.py --world worlds/bormann/office_a.yaml --against ../main
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.s3server import make_bucket, s3_server  # noqa: E402

MB = 1 << 20


def _rss_mb() -> float:
    """This process's resident memory now [MiB]."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def bench_clients(env: dict[str, str], size_mb: int) -> dict[str, dict[str, float]]:
    """Upload and streamed download of one `size_mb` object and of 20 small files, by each."""
    from minio import Minio

    from worker.storage.s3 import S3Storage

    data = os.urandom(size_mb * MB)
    out: dict[str, dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        big = Path(tmp) / "big.bin"
        big.write_bytes(data)
        b3 = S3Storage(make_bucket(env))
        t0 = time.perf_counter()
        b3.put_file("big.bin", big)
        t1 = time.perf_counter()
        n = sum(len(c) for c in b3.iter_bytes("big.bin"))
        t2 = time.perf_counter()
        out["boto3"] = {"up_MBps": size_mb / (t1 - t0), "down_MBps": n / MB / (t2 - t1)}
        host = env["AWS_ENDPOINT_URL"].split("://", 1)[1]
        key, secret = env["AWS_ACCESS_KEY_ID"], env["AWS_SECRET_ACCESS_KEY"]
        mc = Minio(host, access_key=key, secret_key=secret, secure=False, region="us-east-1")
        bucket = make_bucket(env)
        t0 = time.perf_counter()
        mc.fput_object(bucket, "big.bin", str(big))
        t1 = time.perf_counter()
        resp = mc.get_object(bucket, "big.bin")
        n = sum(len(c) for c in resp.stream(MB))
        resp.close()
        t2 = time.perf_counter()
        out["minio"] = {"up_MBps": size_mb / (t1 - t0), "down_MBps": n / MB / (t2 - t1)}
    return out


def _api_rss_mb(pid: int) -> float:
    """The resident memory of process `pid` (the API: uvicorn with one worker) [MiB]."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:  # it ended
        pass
    return 0.0


def _stored_run(tmp: Path) -> tuple[str, str, int, Path]:
    """A sqlite database with a real finished run (odometry, 60 s) and its folder: (url, api
    key, run id, folder)."""
    from backend.db.migrate import upgrade
    from backend.db.session import session_scope
    from backend.store import add_user
    from tests.worker.export.runs import finished_run, store_run

    url = f"sqlite:///{tmp}/m.db"
    upgrade(url)
    with session_scope(url) as s:
        user, key = add_user(s, "bench")
        uid = user.id
    folder = tmp / "report"
    run_id = store_run(url, uid, finished_run(folder), folder)
    return url, key, run_id, folder


def _serve_and_stream(python: str, tree: Path, env: dict[str, str], url: str, key: str,
                      path: str) -> dict[str, float]:  # fmt: skip
    """Start the API of checkout `tree`, stream GET `path` once, sample its memory."""
    import threading

    import httpx

    port = 18000 + os.getpid() % 1000
    e = dict(os.environ, **env, DATABASE_URL=url, PYTHONPATH=str(tree))
    proc = subprocess.Popen([python, "-m", "mapqual", "serve", "--port", str(port),
                             "--no-migrate"], cwd=tree, env=e, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)  # fmt: skip
    try:
        base = f"http://127.0.0.1:{port}"
        for _ in range(300):
            try:
                if httpx.get(f"{base}/healthz", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.2)
        headers = {"Authorization": f"Bearer {key}"}
        warm = httpx.get(base + path.replace("report.zip", "relations"), headers=headers)
        assert warm.status_code == 200, warm.text  # the storage client made, the code loaded
        before, peak, done = _api_rss_mb(proc.pid), [0.0], threading.Event()

        def sample() -> None:
            while not done.is_set():
                peak[0] = max(peak[0], _api_rss_mb(proc.pid))
                time.sleep(0.02)

        threading.Thread(target=sample, daemon=True).start()
        n, t0 = 0, time.perf_counter()
        with httpx.stream("GET", base + path, headers=headers, timeout=120) as r:
            assert r.status_code == 200, r.status_code
            for chunk in r.iter_bytes(MB):
                n += len(chunk)
        dt = time.perf_counter() - t0
        done.set()
        return {"MB": n / MB, "MBps": n / MB / dt, "api_rss_growth_MB": peak[0] - before}
    finally:
        proc.terminate()
        proc.wait(timeout=20)


def bench_stream(env: dict[str, str], size_mb: int, against: Path | None) -> dict[str, object]:
    """GET /runs/{id}/report.zip of a `size_mb` zip: this checkout's API streaming it from S3
    (and from the local folder), the other checkout's API serving it from the local folder."""
    import sqlite3

    from worker.storage.s3 import S3Storage

    out: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        url, key, run_id, folder = _stored_run(tmp)
        with (folder / "report.zip").open("wb") as f:  # the size of a two-hour run's zip
            for _ in range(size_mb):
                f.write(os.urandom(MB))
        bucket = make_bucket(env)
        store = S3Storage(bucket)
        store.put_tree(f"runs/{run_id}/a", folder)
        path = f"/api/v1/runs/{run_id}/report.zip"
        for where in ("s3", "local", "against_local"):
            tree = against if where == "against_local" else ROOT
            if tree is None:
                continue
            loc = store.location(f"runs/{run_id}/a") if where == "s3" else str(folder)
            with sqlite3.connect(tmp / "m.db") as c:  # the same run, in S3 or in the folder
                c.execute("UPDATE runs SET report_dir = ? WHERE id = ?", (loc, run_id))
            python = tree / ".venv/bin/python"
            python = python if python.exists() else Path(sys.executable)
            out[where] = _serve_and_stream(str(python), tree, env, url, key, path)
    return out


def _timed_run(python: str, cwd: Path, world: str, limit: float, env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run([python, "-m", "mapqual", "run", str(Path(world).resolve()), "--time-limit",
                    str(limit), "--json"], cwd=cwd, env=env, check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    return time.perf_counter() - t0


def bench_run(env: dict[str, str], world: str, limit: float, reps: int,
              against: Path | None) -> dict[str, float]:  # fmt: skip
    """Wall time of whole `mapqual run`s: local folder, S3, and the other checkout (local),
    interleaved so that the machine's load falls on each alike; the medians."""
    bucket = make_bucket(env)
    base = {k: v for k, v in os.environ.items() if k != "MAPQUAL_STORAGE"}
    times: dict[str, list[float]] = {"local": [], "s3": [], "against_local": []}
    for rep in range(reps + 1):  # the first round compiles and caches numba's kernels
        for kind in times:
            if kind == "against_local" and against is None:
                continue
            with tempfile.TemporaryDirectory() as tmp:
                e = dict(base, **env, DATABASE_URL=f"sqlite:///{tmp}/m.db",
                         MAPQUAL_RUNS_DIR=f"{tmp}/runs")  # fmt: skip
                if kind == "s3":
                    e["MAPQUAL_STORAGE"] = f"s3://{bucket}/{uuid.uuid4().hex[:6]}"
                tree = against if kind == "against_local" else ROOT
                python = str(tree / ".venv/bin/python")
                if not Path(python).exists():
                    python = sys.executable
                e["PYTHONPATH"] = str(tree)
                dt = _timed_run(python, Path(tmp), world, limit, e)
                if rep:
                    times[kind].append(dt)
    med = {k: sorted(v)[len(v) // 2] for k, v in times.items() if v}
    med["s3_over_local"] = med["s3"] / med["local"]
    if "against_local" in med:
        med["s3_over_against"] = med["s3"] / med["against_local"]
    return med


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="worlds/bormann/office_a.yaml")
    ap.add_argument("--time-limit", type=float, default=60.0)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--zip-mb", type=int, default=480, help="report.zip size (a 2 h run's)")
    ap.add_argument("--client-mb", type=int, default=100)
    ap.add_argument("--against", type=Path, default=None, help="another checkout (main)")
    ap.add_argument("--only", choices=["clients", "stream", "run"], default=None)
    a = ap.parse_args()
    with s3_server() as env:
        res: dict[str, object] = {}
        if a.only in (None, "clients"):
            res["clients"] = bench_clients(env, a.client_mb)
        if a.only in (None, "stream"):
            res["stream"] = bench_stream(env, a.zip_mb, a.against)
        if a.only in (None, "run"):
            res["run"] = bench_run(env, a.world, a.time_limit, a.reps, a.against)
    print(json.dumps(res, indent=2))


if __name__ == "__main__":
    main()
