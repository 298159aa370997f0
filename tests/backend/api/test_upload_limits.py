"""Upload attacks against a real server process (uvicorn on a free port, real PostgreSQL): a
decompression bomb, a 100 MP one-colour PNG, a chunked body and a Content-Length over the
limit, a YAML naming another owner's report file. Each is answered at once, with the server's
memory (VmRSS) and CPU time (utime + stime) measured around it."""

from __future__ import annotations

import io
import os
import select
import socket
import struct
import subprocess
import sys
import time
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import numpy as np
import pytest
from PIL import Image

from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user
from tests.services import api_server, ensure_redis, scratch_database

LIMIT = 20 * 1024 * 1024  # the default MAPQUAL_MAX_UPLOAD_BYTES
MB = 1024 * 1024


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A migrated PostgreSQL database, users alice and bob, and `uvicorn mapqual.app:app`."""
    runs_dir = tmp_path_factory.mktemp("runs")
    with scratch_database("mapqual_limits") as db_url:
        upgrade(db_url)
        with session_scope(db_url) as s:
            keys = {name: add_user(s, name)[1] for name in ("alice", "bob")}
        env = {
            **os.environ,
            "DATABASE_URL": db_url,
            "REDIS_URL": ensure_redis().rsplit("/", 1)[0] + "/13",
            "MAPQUAL_AUTH": "on",
            "MAPQUAL_RUNS_DIR": str(runs_dir),
        }
        with api_server(env) as (base, proc):
            port = int(base.rsplit(":", 1)[1])
            yield {"base": base, "port": port, "pid": proc.pid, "keys": keys, "runs": runs_dir}


class Usage:
    """The server process's resident memory and CPU time, before and after a request."""

    def __init__(self, pid: int):
        self.pid = pid
        self.rss0, self.cpu0 = self.rss(), self.cpu()

    def rss(self) -> int:
        """VmRSS [bytes] from /proc/PID/status."""
        for line in Path(f"/proc/{self.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
        raise AssertionError("no VmRSS")

    def cpu(self) -> float:
        """utime + stime [s] from /proc/PID/stat (fields 14 and 15)."""
        stat = Path(f"/proc/{self.pid}/stat").read_text()
        fields = stat[stat.rindex(")") + 2 :].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def grown(self) -> tuple[int, float]:
        return self.rss() - self.rss0, self.cpu() - self.cpu0


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))


def _png_header(w: int, h: int) -> bytes:
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0))


def bomb_png() -> bytes:
    """A few hundred bytes declaring 100,000 x 100,000 grey pixels."""
    return (
        _png_header(100_000, 100_000)
        + _chunk(b"IDAT", zlib.compress(b"\0" * 64))
        + (_chunk(b"IEND", b""))
    )


def one_colour_png(side: int = 10_000) -> bytes:
    """A real, complete side x side white PNG (~100 KB), compressed row by row."""
    comp = zlib.compressobj(9)
    row = b"\0" + b"\xff" * side
    data = b"".join(comp.compress(row) for _ in range(side)) + comp.flush()
    return _png_header(side, side) + _chunk(b"IDAT", data) + _chunk(b"IEND", b"")


def _post_world(server, files, user="alice", **params) -> httpx.Response:
    return httpx.post(
        f"{server['base']}/api/v1/worlds",
        headers={"Authorization": f"Bearer {server['keys'][user]}"},
        files=[("file", f) for f in files],
        data={"resolution": "0.05"},
        params=params,
        timeout=30,
    )


def _worlds(server, user="alice") -> list:
    headers = {"Authorization": f"Bearer {server['keys'][user]}"}
    return httpx.get(f"{server['base']}/api/v1/worlds", headers=headers, timeout=10).json()


@pytest.mark.parametrize(
    ("name", "make", "needle"),
    [
        ("bomb.png", bomb_png, "25,000,000"),
        ("big.png", one_colour_png, "10000 x 10000 = 100,000,000 pixels, more than the limit"),
    ],
)
def test_a_small_file_declaring_huge_images_is_413_at_once_and_cheap(server, name, make, needle):
    body = make()
    assert len(body) < 200_000
    _post_world(server, [("warm.png", b"not a png", "image/png")])  # first-request costs
    usage = Usage(server["pid"])
    t0 = time.monotonic()
    r = _post_world(server, [(name, body, "image/png")], wait=30)
    elapsed = time.monotonic() - t0
    rss, cpu = usage.grown()
    print(f"{name}: {r.status_code} in {elapsed:.3f} s, RSS +{rss / MB:.1f} MB, CPU {cpu:.3f} s")
    assert r.status_code == 413, r.text
    assert needle in r.json()["detail"] and f"{name}: " in r.json()["detail"]
    assert elapsed < 1.0
    assert rss < 100 * MB, f"the server grew by {rss / MB:.0f} MB"
    assert cpu < 0.5, f"the server spent {cpu:.2f} s of CPU"
    assert _worlds(server) == []


def _raw_request(port: int, head: bytes) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", port), timeout=10)
    sock.sendall(head)
    return sock


def _head(server, extra: str) -> bytes:
    return (
        f"POST /api/v1/worlds HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"Authorization: Bearer {server['keys']['alice']}\r\n"
        f"Content-Type: multipart/form-data; boundary=XyZ\r\n{extra}\r\n"
    ).encode()


def _status(sock: socket.socket) -> int:
    data = b""
    while b"\r\n" not in data:
        got = sock.recv(4096)
        if not got:
            break
        data += got
    return int(data.split(b" ", 2)[1])


def test_a_content_length_over_the_limit_is_413_before_any_body(server):
    usage = Usage(server["pid"])
    t0 = time.monotonic()
    sock = _raw_request(server["port"], _head(server, f"Content-Length: {10 * LIMIT}\r\n"))
    with sock:
        assert _status(sock) == 413  # answered with no byte of the body sent
    assert time.monotonic() - t0 < 1.0
    assert usage.grown()[0] < 100 * MB


def test_a_chunked_body_over_the_limit_is_413_before_it_is_all_sent(server):
    usage = Usage(server["pid"])
    body_size = 10 * LIMIT  # 200 MB offered
    part = b"--XyZ\r\nContent-Disposition: form-data; name=file; filename=a.png\r\n\r\n"
    piece = b"\0" * (256 * 1024)
    sock = _raw_request(server["port"], _head(server, "Transfer-Encoding: chunked\r\n"))
    sent, answered = 0, False
    with sock:
        sock.sendall(b"%x\r\n%s\r\n" % (len(part), part))
        try:
            while sent < body_size:
                if select.select([sock], [], [], 0)[0]:
                    answered = True
                    break
                sock.sendall(b"%x\r\n%s\r\n" % (len(piece), piece))
                sent += len(piece)
        except (BrokenPipeError, ConnectionResetError):
            answered = True  # the server answered and closed while we were still sending
        status = _status(sock) if answered else None
    print(f"chunked: answered {status} after {sent / MB:.1f} MB sent")
    assert answered and sent < 2 * LIMIT, f"sent {sent / MB:.0f} MB before an answer"
    assert status in (413, None)  # None: the reset arrived before we could read the 413
    rss, _ = usage.grown()
    assert rss < 100 * MB, f"the server grew by {rss / MB:.0f} MB"
    assert _worlds(server) == []


def test_a_yaml_naming_another_owners_report_file_is_400_and_stores_nothing(server):
    # bob's run report: a real file under the runs folder
    report = server["runs"] / "7" / "map.png"
    report.parent.mkdir(parents=True, exist_ok=True)
    img = np.full((40, 60), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    Image.fromarray(img).save(report)
    up = "../" * 20 + str(report).lstrip("/")
    for value in (str(report), up):
        yaml = f"image: {value}\nresolution: 0.05\n".encode()
        r = _post_world(server, [("steal.yaml", yaml, "application/yaml")], wait=30)
        assert r.status_code == 400, r.text
        detail = r.json()["detail"]
        assert "`image`" in detail and "outside" in detail and "\n" not in detail
    assert _worlds(server) == []


def test_analysis_and_prediction_run_in_limited_processes_and_the_api_never_loads_numba(server):
    img = np.full((40, 60), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    r = _post_world(server, [("room.png", buf.getvalue(), "image/png")], wait=30)
    assert r.status_code == 201 and r.json()["status"] == "ready", r.text
    hdr = {"Authorization": f"Bearer {server['keys']['alice']}"}
    url = f"{server['base']}/api/v1/worlds/{r.json()['id']}/prediction"
    p = httpx.get(url, headers=hdr, timeout=60)
    assert p.status_code == 200 and p.json()["features"]["free_area_m2"] > 0, p.text
    children = Path(f"/proc/{server['pid']}/task/{server['pid']}/children").read_text().split()
    cmdlines = [Path(f"/proc/{pid}/cmdline").read_bytes() for pid in children]
    assert sum(b"sandbox.child\0analysis" in c for c in cmdlines) == 1  # world_workers
    assert sum(b"sandbox.child\0sandbox" in c for c in cmdlines) == 2  # sandbox_workers
    maps = Path(f"/proc/{server['pid']}/maps").read_text()
    assert "llvmlite" not in maps and "/numba/" not in maps
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", "import mapqual.app"],
        capture_output=True,
        text=True,
        check=True,
    )
    assert " numba" not in out.stderr


def test_the_same_upload_sent_twice_at_once_makes_one_world(server):
    img = np.full((30, 50), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    files = [("twin.png", buf.getvalue(), "image/png")]
    with ThreadPoolExecutor(4) as ex:
        answers = list(ex.map(lambda _: _post_world(server, files, user="bob"), range(4)))
    assert all(r.status_code in (200, 202) for r in answers), [r.text for r in answers]
    assert len({r.json()["id"] for r in answers}) == 1
    assert len(_worlds(server, "bob")) == 1
