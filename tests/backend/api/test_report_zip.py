"""GET /runs/{id}/report.zip: the zip a run's result was stored with is served as it is; a
run stored without one (before runs had it, or in a folder of `mapqual run -o` or a batch)
gets one made on its first download and kept."""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np

from backend.db.session import session_scope
from backend.store import mark_run_started, store_run_result
from tests.backend.api.test_worlds_jobs import _png, _upload
from tests.summaries import make_summary
from worker.report.folder import REPORT_ZIP, write_report_zip


def _done_run(api, folder: Path) -> int:
    """A run marked done with `folder` as its report folder (its result: two poses)."""
    w = _upload(api, [("box.png", _png(), "image/png")], resolution="0.05").json()
    run_id = api.post("/api/v1/jobs", json={"world_id": w["id"], "runs": 1}).json()["runs"][0]["id"]
    folder.mkdir(parents=True)
    (folder / "summary.json").write_text('{"outcome": "completed"}\n')
    (folder / "sim.log").write_bytes(b"ODOM 1 2 3\n" * 500)
    with session_scope(api.url) as s:
        mark_run_started(s, run_id)
        store_run_result(
            s, run_id, summary=make_summary(), t=np.array([0.0, 0.1]),
            pose_gt=np.zeros((2, 3)), pose_est=np.zeros((2, 3)), map_ros=np.zeros((2, 2), np.int8),
            map_resolution=0.05, map_origin=(0.0, 0.0), report_dir=str(folder),
        )  # fmt: skip
    return run_id


def _names(content: bytes) -> list[str]:
    with zipfile.ZipFile(io.BytesIO(content)) as zf:
        assert zf.testzip() is None
        return sorted(zf.namelist())


def test_a_run_stored_without_a_zip_gets_one_made_once_on_its_first_download(api, tmp_path):
    folder = tmp_path / "old_run"
    run_id = _done_run(api, folder)
    assert not (folder / REPORT_ZIP).exists()
    r = api.get(f"/api/v1/runs/{run_id}/report.zip")
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/zip"
    assert r.headers["content-disposition"] == f'attachment; filename="run{run_id}.zip"'
    assert _names(r.content) == [f"run{run_id}/sim.log", f"run{run_id}/summary.json"]
    with zipfile.ZipFile(io.BytesIO(r.content)) as zf:
        assert zf.read(f"run{run_id}/sim.log") == (folder / "sim.log").read_bytes()
    made = (folder / REPORT_ZIP).stat().st_mtime_ns
    assert api.get(f"/api/v1/runs/{run_id}/report.zip").content == r.content
    assert (folder / REPORT_ZIP).stat().st_mtime_ns == made  # kept, not made again


def test_the_zip_on_disk_is_served_as_it_is(api, tmp_path):
    folder = tmp_path / "new_run"
    run_id = _done_run(api, folder)
    write_report_zip(folder, f"run{run_id}")  # as the run service does before the commit
    (folder / "late.txt").write_text("written after the zip\n")
    r = api.get(f"/api/v1/runs/{run_id}/report.zip")
    assert r.status_code == 200 and r.content == (folder / REPORT_ZIP).read_bytes()
    assert f"run{run_id}/late.txt" not in _names(r.content)
