"""The Celery side of a batch with the database replaced by a queue in memory: what is sent
(once, across invocations; failed runs with --retry-failed only), and how runs are recorded as
the workers finish them."""

from __future__ import annotations

from typing import Any

import pytest

from tests.summaries import summary_doc
from worker.batch import remote
from worker.batch.experiment import RunSpec
from worker.batch.remote import RunState, record_from_run, run_celery
from worker.batch.state import BatchDir


def _spec(seed: int) -> RunSpec:
    return RunSpec(
        key=f"k{seed}", world_path="/w/a.yaml", world="a", base="a", variant="no_furniture",
        slam="odometry", noise=0.0, seed=seed, params={},
    )  # fmt: skip


class FakeQueue:
    """Runs 1..n; a sent run is running at the next poll and done at the one after."""

    def __init__(self, status: dict[int, str]):
        self.status = dict(status)
        self.sent: list[tuple[int, bool]] = []
        self.polls = 0

    def run_id(self, spec: RunSpec) -> int:
        return spec.seed

    def ids(self, spec: RunSpec) -> dict[str, Any]:
        return {"run_id": spec.seed, "job_id": 100}

    def send(self, run_id: int, requeue: bool) -> None:
        self.sent.append((run_id, requeue))
        self.status[run_id] = "queued"

    def states(self, run_ids) -> list[RunState]:
        self.polls += 1
        out = []
        for i in run_ids:
            st = self.status[i]
            summary = summary_doc(outcome="completed") if st == "done" else None
            progress = {"t": 5.0, "coverage": 0.5} if st == "running" else {}
            error = "boom" if st == "failed" else None
            out.append(RunState(i, st, summary, error, f"/runs/{i}", progress))
            self.status[i] = {"queued": "running", "running": "done"}.get(st, st)
        return out


@pytest.fixture(autouse=True)
def _no_wait(monkeypatch):
    monkeypatch.setattr(remote, "POLL_S", 0.0)


def test_unsent_runs_are_sent_once_and_recorded_as_they_finish(tmp_path):
    bdir, events = BatchDir(tmp_path), []
    queue = FakeQueue({1: "queued", 2: "queued", 3: "done"})
    run_celery([_spec(1), _spec(2), _spec(3)], bdir, queue, events.append)
    assert queue.sent == [(1, False), (2, False)]  # run 3 is done already: collected, not sent
    records = bdir.load_records(["k1", "k2", "k3"])
    assert {k: (r["status"], r["run_id"], r["job_id"]) for k, r in records.items()} == {
        "k1": ("done", 1, 100), "k2": ("done", 2, 100), "k3": ("done", 3, 100),
    }  # fmt: skip
    kinds = [(e.kind, e.spec.key) for e in events]
    assert kinds.count(("finish", "k1")) == 1 and ("start", "k1") in kinds
    assert ("progress", "k1") in kinds and ("start", "k3") not in kinds
    # a second invocation sends nothing again: the journal says both went out
    again = FakeQueue({1: "running", 2: "queued", 3: "done"})
    run_celery([_spec(1), _spec(2), _spec(3)], bdir, again, lambda e: None)
    assert again.sent == []


def test_failed_runs_are_recorded_as_errors_or_resent_with_retry_failed(tmp_path):
    bdir = BatchDir(tmp_path)
    queue = FakeQueue({1: "failed", 2: "cancelled"})
    run_celery([_spec(1), _spec(2)], bdir, queue, lambda e: None)
    assert queue.sent == []
    records = bdir.load_records(["k1", "k2"])
    assert (records["k1"]["status"], records["k1"]["error"]) == ("error", "boom")
    assert (records["k2"]["status"], records["k2"]["error"]) == ("error", "cancelled")
    retry = FakeQueue({1: "failed", 2: "cancelled"})
    run_celery([_spec(1), _spec(2)], BatchDir(tmp_path / "b"), retry, lambda e: None,
               retry_failed=True)  # fmt: skip
    assert retry.sent == [(1, True)]  # requeued first; a cancelled run stays cancelled


def test_a_run_still_queued_or_running_has_no_record_yet():
    spec = _spec(1)
    for status in ("queued", "running"):
        assert record_from_run(spec, RunState(1, status), {}) is None
    done = record_from_run(spec, RunState(1, "done", summary_doc(outcome="failed"), None, "/r"), {})
    assert done is not None and (done["status"], done["report_dir"]) == ("done", "/r")
