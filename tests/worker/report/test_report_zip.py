"""report.zip: every file of the folder under one root, never itself, and written whole or
not at all when several writers race (the API makes it for runs stored without one)."""

from __future__ import annotations

import threading
import zipfile
from pathlib import Path

from worker.report.folder import REPORT_ZIP, write_report_zip


def _folder(root: Path) -> dict[str, bytes]:
    files = {
        "summary.json": b'{"outcome": "completed"}\n',
        "sim.log": b"FLASER 0 0.0 0.0 0.0 1 2 3 4\n" * 1000,
        "sub/deep.txt": b"x",
    }
    for rel, data in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    return files


def _contents(path: Path) -> dict[str, bytes]:
    with zipfile.ZipFile(path) as zf:
        assert zf.testzip() is None
        return {name: zf.read(name) for name in zf.namelist()}


def test_the_zip_holds_every_file_under_its_root_and_not_itself(tmp_path):
    files = _folder(tmp_path)
    path = write_report_zip(tmp_path, "run7")
    assert path == tmp_path / REPORT_ZIP
    assert _contents(path) == {f"run7/{rel}": data for rel, data in files.items()}
    again = write_report_zip(tmp_path, "run7")  # a second zip does not swallow the first
    assert set(_contents(again)) == {f"run7/{rel}" for rel in files}


def test_racing_writers_leave_one_whole_zip_and_no_temporary_file(tmp_path):
    files = _folder(tmp_path)
    barrier, errors = threading.Barrier(8), []

    def write() -> None:
        barrier.wait()
        try:
            write_report_zip(tmp_path, "run7")
        except Exception as exc:  # noqa: BLE001 - collected for the assertion below
            errors.append(exc)

    threads = [threading.Thread(target=write) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    assert _contents(tmp_path / REPORT_ZIP) == {f"run7/{k}": v for k, v in files.items()}
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        REPORT_ZIP,
        "sim.log",
        "sub",
        "summary.json",
    ]
