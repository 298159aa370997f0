"""GET /runs/{id}/bag and POST / GET /runs/{id}/estimates on a real run, database and files: bags
read back with rosbags, estimates scored on the run's relations, owner-only, hostile uploads."""

from __future__ import annotations

import io
import os
import tempfile
import zipfile
from pathlib import Path

import pytest

from backend.db.session import session_scope
from backend.store import find_user
from tests.worker.export.runs import finished_run, store_run
from worker.export.bag import export_bag


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run") / "report"
    return folder, finished_run(folder)


@pytest.fixture
def run_id(api, run_folder, tmp_path):
    """The run stored as alice's, in a folder of its own (estimates are written into it)."""
    src, result = run_folder
    folder = tmp_path / "report"
    folder.mkdir()
    for f in src.iterdir():
        if f.is_file():
            (folder / f.name).write_bytes(f.read_bytes())
    with session_scope(api.url) as s:
        owner = find_user(s, "alice").id
    return store_run(api.url, owner, result, folder)


def _counts(bag: Path) -> dict[str, int]:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return {c.topic: c.msgcount for c in reader.connections}


def _scans(folder: Path) -> int:
    return sum(
        ln.startswith("ROBOTLASER1 ") for ln in (folder / "sim.log").read_text().splitlines()
    )


def test_the_bag_of_a_run_in_both_formats(api, run_id, run_folder, tmp_path):
    n = _scans(run_folder[0])
    r = api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag1"})
    assert r.status_code == 200, r.text
    assert r.headers["content-disposition"] == f'attachment; filename="run{run_id}.bag"'
    (tmp_path / "a.bag").write_bytes(r.content)
    counts = _counts(tmp_path / "a.bag")
    assert counts["/scan"] == counts["/odom"] == counts["/ground_truth"] == n > 50
    r = api.get(f"/api/v1/runs/{run_id}/bag")  # rosbag2 by default: its directory as a zip
    assert r.status_code == 200 and r.headers["content-type"] == "application/zip"
    with zipfile.ZipFile(io.BytesIO(r.content)) as zf:
        assert sorted(zf.namelist()) == [
            f"run{run_id}/metadata.yaml",
            f"run{run_id}/run{run_id}.mcap",
        ]
        zf.extractall(tmp_path / "b")
    assert _counts(tmp_path / "b" / f"run{run_id}")["/scan"] == n
    left = [p for p in Path(tempfile.gettempdir()).glob("mapqual-build-*")]
    assert left == []  # kept in the run's folder, no temporary folder left behind
    assert api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag3"}).status_code == 422


def test_a_bag_is_built_once_and_again_only_when_the_log_changes(api, run_id, tmp_path):
    folder = tmp_path / "report"  # the run's folder (the run_id fixture's)
    first = api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag1"})
    assert first.status_code == 200
    cached = folder / "export" / f"run{run_id}.bag"
    inode = cached.stat().st_ino
    again = api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag1"})
    assert again.content == first.content and cached.stat().st_ino == inode  # served, not built
    assert sorted(p.name for p in (folder / "export").iterdir()) == [cached.name]  # no leftovers
    log = folder / "sim.log"
    later = cached.stat().st_mtime_ns + 10**9
    os.utime(log, ns=(later, later))  # the log rewritten after the bag: built anew
    rebuilt = api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag1"})
    assert rebuilt.status_code == 200 and cached.stat().st_ino != inode
    assert rebuilt.content == first.content  # the same log, the same bag


def test_a_run_folder_that_cannot_be_written_still_gets_its_bag(api, run_id, tmp_path):
    folder = tmp_path / "report"
    folder.chmod(0o555)
    try:
        if os.access(folder, os.W_OK):  # root writes anywhere: make export/ a file instead
            folder.chmod(0o755)
            (folder / "export").write_text("not a folder")
        r = api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag1"})
    finally:
        folder.chmod(0o755)
    assert r.status_code == 200 and len(r.content) > 1000
    assert list(Path(tempfile.gettempdir()).glob("mapqual-build-*")) == []


def test_four_first_requests_at_once_build_the_bag_once(api, run_id, monkeypatch):
    """Issue 48 item 6 / issue 50: simultaneous first GETs wait for one build, all served."""
    import threading
    from concurrent.futures import ThreadPoolExecutor

    from backend.api.routes import bags

    builds, real = [], bags._build_bag
    gate = threading.Barrier(4)

    def counted(*args, **kw):
        builds.append(args[-1])
        return real(*args, **kw)

    monkeypatch.setattr(bags, "_build_bag", counted)

    def fetch(_):
        gate.wait(timeout=30)
        return api.get(f"/api/v1/runs/{run_id}/bag", params={"format": "rosbag1"})

    with ThreadPoolExecutor(4) as pool:
        answers = list(pool.map(fetch, range(4)))
    assert [r.status_code for r in answers] == [200] * 4
    assert len({r.content for r in answers}) == 1 and len(answers[0].content) > 1000
    assert builds == ["rosbag1"]


def test_an_estimate_is_scored_on_the_runs_relations_and_listed(api, run_id, run_folder):
    folder, result = run_folder
    body = (folder / "est.tum").read_bytes()
    r = api.post(f"/api/v1/runs/{run_id}/estimates", files={"file": ("mine.tum", body)},
                 data={"name": "mine"})  # fmt: skip
    assert r.status_code == 201, r.text
    out = r.json()
    ours = result.summary.relations["B"]
    assert out["name"] == "mine" and out["source"] == "mine.tum"
    assert out["b_mean_t"] == pytest.approx(ours.translation.mean, abs=1e-8)
    assert out["metrics"]["relations"]["B"]["translation"]["n"] == ours.translation.n
    listed = api.get(f"/api/v1/runs/{run_id}/estimates").json()
    assert [e["name"] for e in listed] == ["mine"]
    # the same name again replaces it
    again = api.post(f"/api/v1/runs/{run_id}/estimates", files={"file": ("x.tum", body)},
                     data={"name": "mine"})  # fmt: skip
    assert again.status_code == 201 and len(api.get(f"/api/v1/runs/{run_id}/estimates").json()) == 1
    page = api.client.get(f"/jobs/{_job_of(api, run_id)}", headers=api._auth("alice"))
    assert page.status_code == 200 and "odometry (this run)" in page.text and ">mine<" in page.text
    assert f"/api/v1/runs/{run_id}/bag?format=rosbag1" in page.text
    compare = api.client.get("/compare", headers=api._auth("alice")).text
    assert "External algorithms on the same runs" in compare and "<td>mine</td>" in compare
    assert "<td>mine</td>" not in api.client.get("/compare", headers=api._auth("bob")).text


def _job_of(api, run_id: int) -> int:
    from backend.db.models import Run

    with session_scope(api.url) as s:
        return s.get_one(Run, run_id).job_id


def test_a_rosbag2_zip_with_a_topic_is_scored(api, run_id, run_folder, tmp_path):
    export_bag(run_folder[0], tmp_path / "bag", "rosbag2")
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as zf:
        for f in (tmp_path / "bag").iterdir():
            zf.write(f, f"bag/{f.name}")
    r = api.post(f"/api/v1/runs/{run_id}/estimates", files={"file": ("odom.zip", buf.getvalue())},
                 data={"name": "odom", "topic": "/odom"})  # fmt: skip
    assert r.status_code == 201, r.text
    assert r.json()["b_mean_t"] == pytest.approx(
        run_folder[1].summary.relations["B"].translation.mean, abs=1e-5
    )


def test_a_bare_mcap_file_is_scored(api, run_id, run_folder, tmp_path):
    export_bag(run_folder[0], tmp_path / "bag", "rosbag2")
    mcap = (tmp_path / "bag" / "bag.mcap").read_bytes()  # without its metadata.yaml
    r = api.post(f"/api/v1/runs/{run_id}/estimates", files={"file": ("rec.mcap", mcap)},
                 data={"name": "bare", "topic": "/odom"})  # fmt: skip
    assert r.status_code == 201, r.text
    want = run_folder[1].summary.relations["B"].translation.mean
    assert r.json()["b_mean_t"] == pytest.approx(want, abs=1e-5)


def _zip(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return buf.getvalue()


@pytest.mark.parametrize(
    ("name", "body", "form", "needle"),
    [
        ("ms.tum", "ms", {}, "milliseconds instead of seconds"),
        (
            "evil.zip",
            _zip({"metadata.yaml": b"x", "../evil.mcap": b"y"}),
            {},
            "not beside metadata.yaml",
        ),
        ("bomb.zip", _zip({"metadata.yaml": b"0" * 5_000_000}), {}, "metadata.yaml holds"),
        ("no.zip", b"PK\x03\x04 not really", {}, "not a readable zip"),
        ("junk.bag", b"#ROSBAG V2.0\n" + b"\x00" * 100, {}, "not a readable ROS bag"),
        ("junk.mcap", b"\x89MCAP0\r\n" + b"\xff" * 64, {}, "not a readable ROS bag"),
        ("junk.db3", b"SQLite format 3\x00" + b"\x01" * 200, {}, "not a readable ROS bag"),
        (
            "meta.zip",
            _zip({"b/metadata.yaml": b"rosbag2_bagfile_information: 7\n"}),
            {},
            "not a readable ROS bag",
        ),
        ("bad name!.tum", "ok", {}, "unsafe file name"),
        ("ok.tum", "ok", {"name": "../x"}, "estimate name"),
        ("junk.tum", b"1 2 3\n", {}, "expected 8"),
    ],
    ids=[
        "ms",
        "zip-slip",
        "zip-bomb",
        "bad-zip",
        "bad-bag",
        "bad-mcap",
        "bad-db3",
        "bad-meta",
        "path",
        "name",
        "junk",
    ],
)
def test_bad_estimates_are_refused_in_one_line(api, run_id, run_folder, name, body, form, needle):
    est = (run_folder[0] / "est.tum").read_text()
    if body == "ms":
        rows = [ln.split() for ln in est.splitlines() if not ln.startswith("#")]
        body = "".join(f"{float(r[0]) * 1000:.3f} {' '.join(r[1:])}\n" for r in rows)
    elif body == "ok":
        body = est
    r = api.post(f"/api/v1/runs/{run_id}/estimates", files={"file": (name, body)}, data=form)
    assert r.status_code == 400, r.text
    detail = r.json()["detail"]
    assert needle in detail and "\n" not in detail and "/tmp" not in detail


def test_estimates_are_the_owners_only(api, run_id, run_folder):
    body = (run_folder[0] / "est.tum").read_bytes()
    for caller, code in (("bob", 404), (None, 401)):
        r = api.post(
            f"/api/v1/runs/{run_id}/estimates", user=caller, files={"file": ("e.tum", body)}
        )
        assert r.status_code == code, r.text
        assert api.get(f"/api/v1/runs/{run_id}/estimates", user=caller).status_code == code
        assert api.get(f"/api/v1/runs/{run_id}/bag", user=caller).status_code == code
    r = api.post(f"/api/v1/runs/{run_id}/estimates", user="admin", files={"file": ("e.tum", body)})
    assert r.status_code == 201
    assert api.get(f"/api/v1/runs/{run_id}/estimates").json()[0]["name"] == "external"


def test_an_upload_over_the_limit_is_413(api, run_id):
    big = b"0" * (21 * 1024 * 1024)  # the API's default limit is 20 MiB
    r = api.post(f"/api/v1/runs/{run_id}/estimates", files={"file": ("big.tum", big)})
    assert r.status_code == 413
