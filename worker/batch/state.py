"""A batch's output folder as its resumable state: one record per finished run, and a journal.

A run is finished once `runs/<key>/record.json` exists; the record is written last and
atomically (temporary file, then rename), so a batch killed at any moment leaves either a
complete record or none, and resuming re-does only the runs without one.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import uuid
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from worker.batch.experiment import RunSpec
from worker.batch.records import BatchRecord
from worker.errors import InputError
from worker.report.summary import RunSummary
from worker.status import RecordStatus

RECORD = "record.json"
BATCH = "batch.json"
JOURNAL = "journal.jsonl"
LOCK = ".lock"  # held by the batch process writing the folder (BatchDir.lock)


def now_iso() -> str:
    """UTC time stamp, ISO 8601 to the second."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def record_of(
    spec: RunSpec,
    *,
    summary: RunSummary | None,
    error: str | None = None,
    run_id: int | None = None,
    job_id: int | None = None,
    report_dir: str | None = None,
) -> BatchRecord:
    """A finished run's record: its labels, and its summary or the error that stopped it.

    `status` is `RecordStatus.DONE` when the pipeline finished the run (whatever the
    exploration's outcome), `ERROR` when it raised: the tables count such a run as failed,
    reason "error".
    In memory `summary` is the typed summary; record.json holds its persisted form.
    """
    return {
        **asdict(spec),
        "status": RecordStatus.DONE if summary is not None else RecordStatus.ERROR,
        "error": error,
        "summary": summary,
        "run_id": run_id,
        "job_id": job_id,
        "report_dir": report_dir,
        "finished_at": now_iso(),
    }


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


class BatchDir:
    """The output folder OUT of a batch: records, journal, tables, plots, report.html."""

    def __init__(self, root: str | Path):
        self.root = Path(root)  # created on the first write, so a dry run leaves no trace
        self.runs = self.root / "runs"

    def batch_id(self) -> str:
        """This folder's batch id, made on first use: it names the batch's jobs in the database."""
        path = self.root / BATCH
        if path.exists():
            return json.loads(path.read_text())["batch_id"]
        bid = uuid.uuid4().hex[:12]
        self.root.mkdir(parents=True, exist_ok=True)
        _write_atomic(path, json.dumps({"batch_id": bid, "created": now_iso()}, indent=2) + "\n")
        return bid

    @contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the folder for one batch process: a second one on the same OUT would run
        the same runs again and write their records and the database's jobs over the first's.
        An exclusive flock on OUT/.lock (released by the kernel when the process ends, killed
        or not, so a stale lock cannot outlive a crash); held: InputError."""
        self.root.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.root / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.pread(fd, 32, 0).decode("ascii", "replace").strip() or "?"
                raise InputError(
                    f"{self.root} is in use by another mapqual batch (pid {holder}); wait for "
                    "it to end or give another -o"
                ) from None
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
            yield
        finally:
            os.close(fd)  # closing the last descriptor releases the lock

    def describe(self, **info: Any) -> None:
        """Store what the latest invocation asked for beside the batch id (for the report)."""
        path = self.root / BATCH
        doc = json.loads(path.read_text()) if path.exists() else {}
        doc.setdefault("batch_id", self.batch_id())
        doc.update(info, updated=now_iso())
        _write_atomic(path, json.dumps(doc, indent=2) + "\n")

    def info(self) -> dict[str, Any]:
        """batch.json as a mapping."""
        path = self.root / BATCH
        return json.loads(path.read_text()) if path.exists() else {}

    def run_dir(self, key: str) -> Path:
        """The report folder of one run."""
        return self.runs / key

    def fresh_run_dir(self, key: str) -> Path:
        """The run's report folder emptied of an interrupted attempt's leftovers."""
        d = self.run_dir(key)
        if d.exists():
            shutil.rmtree(d)
        d.mkdir(parents=True)
        return d

    def load_records(self, keys: Iterable[str]) -> dict[str, BatchRecord]:
        """The records that exist among `keys` (a run without one is not finished)."""
        out = {}
        for key in keys:
            path = self.run_dir(key) / RECORD
            if path.is_file():
                record = json.loads(path.read_text())
                record["summary"] = RunSummary.load(record["summary"])
                out[key] = record
        return out

    def write_record(self, record: BatchRecord) -> None:
        """Mark a run finished (atomically; the last thing written for a run)."""
        d = self.run_dir(record["key"])
        d.mkdir(parents=True, exist_ok=True)
        s = record["summary"]
        doc = {**record, "summary": None if s is None else s.to_dict()}
        _write_atomic(d / RECORD, json.dumps(doc, indent=1) + "\n")

    def journal(self, event: str, key: str | None = None, **fields: Any) -> None:
        """Append one event (start, done, error, interrupted, enqueued) to journal.jsonl."""
        line = json.dumps({"time": now_iso(), "event": event, "key": key, **fields})
        self.root.mkdir(parents=True, exist_ok=True)
        with open(self.root / JOURNAL, "a", encoding="utf-8") as fh:
            fh.write(line + "\n")
            fh.flush()

    def read_journal(self) -> list[dict[str, Any]]:
        """Every journal event, oldest first (a torn last line from a kill is skipped)."""
        path = self.root / JOURNAL
        if not path.exists():
            return []
        events = []
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                events.append(json.loads(line))
            except json.JSONDecodeError:
                continue
        return events
