"""Uploads that run into the sandbox's own limits, not into a parser's check: CPU seconds
(RLIMIT_CPU), address space (RLIMIT_AS), bytes written (RLIMIT_FSIZE) and the wall-clock
deadline, when an upload is read (the upload sandbox) and when a world that passed that is
analysed (the analysis processes). Each is crafted input against a real server (uvicorn,
PostgreSQL, Redis) whose limits are set low through its environment, as an admin would: each
is answered 400 with one line naming the limit and its setting, within 15 s, cheaply for the
API process (tests/backend/api/test_hostile_uploads.py's measures); no process is left behind
(the server's descendants are its warm parser processes, none with a child); and the next
ordinary upload is accepted."""

from __future__ import annotations

import contextlib
import os
import zlib
from pathlib import Path

import httpx
import pytest

from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user
from tests.backend.api import hostile
from tests.backend.api.test_hostile_uploads import _attack, _tree
from tests.backend.api.test_upload_limits import _chunk, _png_header
from tests.services import api_server, ensure_redis, scratch_database
from tests.worker.export.runs import finished_run, store_run

MB = 1 << 20
SIDE = 4900  # a 24 MP plan: within the default pixel limit (25 MP)

# Three servers, each with the limits its cases run into (and the others out of the way).
SERVERS = {
    "cpu": {"MAPQUAL_SANDBOX_CPU_S": "1", "MAPQUAL_SANDBOX_MEMORY_MB": "512",
            "MAPQUAL_ANALYSIS_CPU_S": "1"},
    "wall": {"MAPQUAL_SANDBOX_CPU_S": "60", "MAPQUAL_SANDBOX_WALL_S": "2",
             "MAPQUAL_ANALYSIS_CPU_S": "600", "MAPQUAL_ANALYSIS_WALL_S": "2"},
    # room for a 24 MP plan's bits (3 MB), and a zip may unpack to far more than that
    "disk": {"MAPQUAL_SANDBOX_TEMP_MB": "8", "MAPQUAL_UPLOAD_UNPACKED_MB": "512",
             "MAPQUAL_ANALYSIS_MEMORY_MB": "512"},
}  # fmt: skip


def slow_yaml() -> bytes:
    """A map_server YAML with 8 MiB of comments: seconds of the YAML scanner's CPU (about
    2.6 MB/s), little memory."""
    line = b"# " + b"x" * 77 + b"\n"
    return b"image: a.png\nresolution: 0.05\n" + line * (8 * MB // len(line))


def plan_png(side: int = SIDE, colour: int = 0) -> bytes:
    """A side x side walled room (grey, or RGBA when `colour` is 6), about 30 kB: decoding
    takes 1 (4) bytes a pixel, analysing its free space far more."""
    channels = 4 if colour == 6 else 1
    comp = zlib.compressobj(9)
    edge = b"\0" + b"\0" * side * channels
    row = b"\0" + b"\0" * channels + b"\xff" * (side - 2) * channels + b"\0" * channels
    rows = [edge] + [row] * (side - 2) + [edge]
    data = b"".join(comp.compress(r) for r in rows) + comp.flush()
    head = bytearray(_png_header(side, side))
    head[25] = colour  # IHDR's colour type; its CRC made again below
    ihdr = bytes(head[12:29])
    head[29:33] = zlib.crc32(ihdr).to_bytes(4, "big")
    return bytes(head) + _chunk(b"IDAT", data) + _chunk(b"IEND", b"")


# (server, case, what is sent, needle of the 400's one line)
CASES = [
    ("cpu", "read-cpu", ("world", "m.yaml", slow_yaml),
     "took more than 1 s of CPU to read (setting sandbox_cpu_s, environment "
     "MAPQUAL_SANDBOX_CPU_S)"),
    ("cpu", "read-memory", ("world", "rgba.png", lambda: plan_png(colour=6)),
     "needs more than 512 MiB of memory to read (setting sandbox_memory_mb"),
    ("cpu", "analysis-cpu", ("world", "big.png", plan_png),
     "took more than 1 s of CPU to analyse (setting analysis_cpu_s"),
    ("wall", "read-wall", ("world", "m.yaml", slow_yaml),
     "took more than 2 s to read (setting sandbox_wall_s, environment MAPQUAL_SANDBOX_WALL_S)"),
    ("wall", "analysis-wall", ("world", "big.png", plan_png),
     "took more than 2 s to analyse (setting analysis_wall_s"),
    ("disk", "read-file-size", ("estimate", "b.zip", hostile.zip_deflate_bomb),
     "needs more than 8 MiB of disk to read (setting sandbox_temp_mb, environment "
     "MAPQUAL_SANDBOX_TEMP_MB)"),
    ("disk", "analysis-memory", ("world", "big.png", plan_png),
     "needs more than 512 MiB of memory to analyse (setting analysis_memory_mb"),
]  # fmt: skip


@pytest.fixture(scope="module")
def run_report(tmp_path_factory):
    report = tmp_path_factory.mktemp("run") / "report"
    return report, finished_run(report)


@pytest.fixture(scope="module")
def servers(tmp_path_factory, run_report):
    """A server per entry of SERVERS, started when a case first needs it."""
    started: dict[str, dict] = {}
    with contextlib.ExitStack() as stack:

        def get(name: str) -> dict:
            if name not in started:
                started[name] = stack.enter_context(_server(tmp_path_factory, run_report, name))
            return started[name]

        yield get


@contextlib.contextmanager
def _server(tmp_path_factory, run_report, name: str):
    runs_dir, tmp = tmp_path_factory.mktemp("runs"), tmp_path_factory.mktemp("servertmp")
    report, result = run_report
    with scratch_database(f"mapqual_limits_{name}") as db_url:
        upgrade(db_url)
        with session_scope(db_url) as s:
            user, key = add_user(s, "alice")
        run_id = store_run(db_url, user.id, result, report)
        env = {
            **os.environ, "DATABASE_URL": db_url, "MAPQUAL_AUTH": "on", "TMPDIR": str(tmp),
            "REDIS_URL": ensure_redis().rsplit("/", 1)[0] + "/11",
            "MAPQUAL_RUNS_DIR": str(runs_dir), **SERVERS[name],
        }  # fmt: skip
        with api_server(env) as (base, proc):
            yield {"base": base, "pid": proc.pid, "key": key, "run": run_id, "tmp": tmp,
                   "report": report}  # fmt: skip


def _send(server, kind: str, name: str, body: bytes) -> httpx.Response:
    hdr = {"Authorization": f"Bearer {server['key']}"}
    if kind == "estimate":
        url = f"{server['base']}/api/v1/runs/{server['run']}/estimates"
        return httpx.post(url, headers=hdr, files={"file": (name, body)}, timeout=60)
    files = [("file", (name, body))]
    if name.endswith(".yaml"):
        files.append(("file", ("a.png", hostile.png_bytes())))
    return httpx.post(
        f"{server['base']}/api/v1/worlds", headers=hdr, params={"wait": 30}, files=files,
        data={} if name.endswith(".yaml") else {"resolution": "0.05"}, timeout=60,
    )  # fmt: skip


def _left_behind(server) -> list[str]:
    """The server's descendants that are not its idle warm parser processes."""
    out = []
    for pid in _tree(server["pid"]) - {server["pid"]}:
        with contextlib.suppress(OSError):
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
            stat = Path(f"/proc/{pid}/stat").read_text()
            parent = int(stat[stat.rindex(")") + 2 :].split()[1])
            if b"backend.sandbox.child" not in cmd or parent != server["pid"]:
                out.append(cmd.replace(b"\0", b" ").decode(errors="replace"))
    return out


@pytest.mark.parametrize(("where", "case", "upload", "needle"), CASES, ids=[c[1] for c in CASES])
def test_a_parse_past_a_limit_is_a_400_and_the_pool_recovers(servers, where, case, upload, needle):
    server = servers(where)
    kind, name, make = upload
    body = make()  # built before the clock starts
    m = _attack(server, lambda: _send(server, kind, name, body))
    r = m["r"]
    print(
        f"{case}: {r.status_code} in {m['s']:.2f} s, RSS +{m['rss'] / MB:.0f} MB, temp "
        f"+{m['tmp'] / MB:.0f} MB, CPU after {m['after_cpu']:.2f} s, healthz {m['health']:.2f} s"
    )
    assert r.status_code == 400, r.text
    detail = r.json()["detail"]
    assert (
        needle in detail
        and detail.startswith(f"{name}: ")
        and "\n" not in detail
        and "/tmp" not in detail
    ), detail
    assert m["s"] < 15.0 and m["rss"] < 300 * MB and m["tmp"] < 100 * MB
    assert m["after_cpu"] < 0.3 and m["health"] < 2.0
    assert _left_behind(server) == []
    ordinary = _send(server, "world", "room.png", hostile.png_bytes(70 + len(case), 50))
    assert ordinary.status_code == 201 and ordinary.json()["status"] == "ready", ordinary.text
    tum = (server["report"] / "est.tum").read_bytes()
    assert _send(server, "estimate", "e.tum", tum).status_code == 201
    assert _left_behind(server) == []
