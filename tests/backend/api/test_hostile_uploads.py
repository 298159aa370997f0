"""The hostile-upload corpus (tests/backend/api/hostile.py) against a real server process
(uvicorn, PostgreSQL, Redis): each upload is answered 4xx within 15 s, the API process grows
by at most 300 MB (VmRSS, sampled), its temporary folder by at most 100 MB, no CPU is burned
after the answer (the server and its descendants), and /healthz answers within 2 s while the
upload is processed. Afterwards an ordinary estimate and world are still accepted, and the
estimate quota answers 429 naming its setting."""

from __future__ import annotations

import contextlib
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import httpx
import pytest

from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user
from tests.backend.api import hostile
from tests.backend.api.test_upload_limits import Usage
from tests.services import api_server, ensure_redis, scratch_database
from tests.worker.export.runs import finished_run, store_run

MB = 1 << 20


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A migrated database, alice with a finished run, and `uvicorn mapqual.app:app` whose
    temporary folder (TMPDIR) is one of the test's, to be measured."""
    runs_dir, tmp = tmp_path_factory.mktemp("runs"), tmp_path_factory.mktemp("servertmp")
    report = tmp_path_factory.mktemp("run") / "report"
    result = finished_run(report)
    with scratch_database("mapqual_hostile") as db_url:
        upgrade(db_url)
        with session_scope(db_url) as s:
            user, key = add_user(s, "alice")
            owner = user.id
        run_id = store_run(db_url, owner, result, report)
        env = {
            **os.environ, "DATABASE_URL": db_url, "MAPQUAL_AUTH": "on", "TMPDIR": str(tmp),
            "REDIS_URL": ensure_redis().rsplit("/", 1)[0] + "/12",
            "MAPQUAL_RUNS_DIR": str(runs_dir), "MAPQUAL_QUOTA_ESTIMATES": "2",
        }  # fmt: skip
        with api_server(env) as (base, proc):
            yield {"base": base, "pid": proc.pid, "key": key, "run": run_id, "tmp": tmp,
                   "report": report}  # fmt: skip


def _auth(server) -> dict[str, str]:
    return {"Authorization": f"Bearer {server['key']}"}


def _estimate(server, name: str, body: bytes, algo: str = "hostile") -> httpx.Response:
    return httpx.post(
        f"{server['base']}/api/v1/runs/{server['run']}/estimates", headers=_auth(server),
        files={"file": (name, body)}, data={"name": algo}, timeout=60,
    )  # fmt: skip


def _world(server, files: list[tuple[str, bytes]], **data) -> httpx.Response:
    return httpx.post(
        f"{server['base']}/api/v1/worlds", headers=_auth(server), params={"wait": 10},
        files=[("file", f) for f in files], data=data, timeout=60,
    )  # fmt: skip


def _tree(pid: int) -> set[int]:
    """`pid` and its descendants."""
    out, level = {pid}, {pid}
    while level:
        kids = set()
        for entry in os.listdir("/proc"):
            if entry.isdigit():
                try:
                    stat = Path(f"/proc/{entry}/stat").read_text()
                except OSError:
                    continue
                if int(stat[stat.rindex(")") + 2 :].split()[1]) in level:
                    kids.add(int(entry))
        level = kids - out
        out |= level
    return out


def _cpu(pids: set[int]) -> float:
    total = 0.0
    for pid in pids:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2 :].split()
        total += (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return total


def _du(folder: Path) -> int:
    total = 0
    for root, _, files in os.walk(folder):
        for f in files:
            with contextlib.suppress(OSError):
                total += os.lstat(os.path.join(root, f)).st_blocks * 512
    return total


def _attack(server, send: Callable[[], httpx.Response]) -> dict:
    """Send one upload while sampling the server; what was measured."""
    usage = Usage(server["pid"])
    tmp0 = _du(server["tmp"])
    peak = {"rss": 0, "tmp": 0, "health": 0.0}
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            peak["rss"] = max(peak["rss"], usage.rss() - usage.rss0)
            peak["tmp"] = max(peak["tmp"], _du(server["tmp"]) - tmp0)
            t0 = time.monotonic()
            ok = httpx.get(f"{server['base']}/healthz", timeout=10).status_code == 200
            peak["health"] = max(peak["health"], time.monotonic() - t0 if ok else 99.0)
            time.sleep(0.05)

    with ThreadPoolExecutor(1) as ex:
        watcher = ex.submit(watch)
        t0 = time.monotonic()
        r = send()
        elapsed = time.monotonic() - t0
        done.set()
        watcher.result()
    pids = _tree(server["pid"])
    cpu0 = _cpu(pids)
    time.sleep(1.0)
    return {"r": r, "s": elapsed, "after_cpu": _cpu(pids) - cpu0, **peak}


CORPUS = [
    ("mcap-zstd-chunk", "b.mcap", hostile.mcap_zstd_bomb, "decompresses to more"),
    ("rosbag1-bz2-chunk", "b.bag", hostile.rosbag1_bz2_bomb, "decompresses to more"),
    ("zip-bzip2-declared-16", "b.zip", hostile.zip_bzip2_declared_16, "method 12 is not accepted"),
    ("zip-deflate-200mb", "b.zip", hostile.zip_deflate_bomb, "unpacks to more than"),
    (
        "rosbag2-file-compression",
        "b.zip",
        hostile.zip_rosbag2_file_compression,
        "compression_mode 'file' is not accepted",
    ),  # noqa: E501
    ("db3-recursive-view", "x.db3", hostile.db3_recursive_view, "holds a view 'schema'"),
    ("tum-gzip", "t.tum", hostile.tum_gzip_bomb, "decompresses to more"),
    ("stage-nested", "w.world", hostile.stage_nested, "nested more than"),
    ("yaml-image-dot", "m.yaml", hostile.yaml_image_dot, "m.yaml: `image` '.' names a folder"),
]


@pytest.mark.parametrize(("case", "name", "make", "needle"), CORPUS, ids=[c[0] for c in CORPUS])
def test_a_hostile_upload_is_refused_cheaply(server, case, name, make, needle):
    body = make()  # built before the clock starts
    if name.endswith((".world", ".yaml")):
        files = [(name, body)] + (
            [("a.png", hostile.png_bytes())] if name.endswith(".world") else []
        )  # noqa: E501
        m = _attack(server, lambda: _world(server, files))
    else:
        m = _attack(server, lambda: _estimate(server, name, body))
    r = m["r"]
    print(
        f"{case}: {r.status_code} in {m['s']:.2f} s, RSS +{m['rss'] / MB:.0f} MB, temp "
        f"+{m['tmp'] / MB:.0f} MB, CPU after {m['after_cpu']:.2f} s, "
        f"healthz {m['health']:.2f} s"
    )
    assert 400 <= r.status_code < 500, r.text
    detail = r.json()["detail"]
    assert needle in detail and "\n" not in detail, detail
    assert "/tmp" not in detail and str(server["tmp"]) not in detail, detail
    assert m["s"] < 15.0
    assert m["rss"] < 300 * MB and m["tmp"] < 100 * MB
    assert m["after_cpu"] < 0.3 and m["health"] < 2.0


def test_a_prediction_for_an_unknown_slam_is_refused_at_once(server):
    r = _world(server, [("box.png", hostile.png_bytes())], resolution="0.05")
    assert r.status_code == 201, r.text
    url = f"{server['base']}/api/v1/worlds/{r.json()['id']}/prediction"
    t0 = time.monotonic()
    bad = httpx.get(url, params={"slam": "bogus1"}, headers=_auth(server), timeout=30)
    assert bad.status_code == 400 and "no 'bogus1' part" in bad.json()["detail"]
    assert time.monotonic() - t0 < 1.0


def test_afterwards_ordinary_uploads_are_accepted_and_the_quota_holds(server):
    tum = (server["report"] / "est.tum").read_bytes()
    for algo in ("mine", "other"):
        r = _estimate(server, "e.tum", tum, algo)
        assert r.status_code == 201, r.text
    third = _estimate(server, "e.tum", tum, "third")
    assert third.status_code == 429
    assert "(setting quota_estimates, environment MAPQUAL_QUOTA_ESTIMATES)" in third.text
    assert _estimate(server, "e.tum", tum, "mine").status_code == 201  # a replacement
    w = _world(server, [("room.png", hostile.png_bytes(90, 70))], resolution="0.05")
    assert w.status_code == 201, w.text
