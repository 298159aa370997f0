"""The process pool: a raising task or a dying worker fails that task only; the rest finish."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import pytest

from worker.batch.pool import TaskFailed, run_pool


def square_or_fail(x, progress):
    """A task for the pool (importable: workers are spawned)."""
    progress(("working", x))
    if x == 3:
        raise ValueError("three is bad")
    if x == 5:
        # the worker dies holding the task, in the middle of sending a large message
        threading.Thread(target=progress, args=(b"x" * 10_000_000,), daemon=True).start()
        time.sleep(0.01)
        os.kill(os.getpid(), signal.SIGKILL)
    return x * x, os.getpid()


def test_failures_stay_with_their_task_and_a_dead_worker_is_replaced():
    messages = []
    run_pool(square_or_fail, list(range(8)), 2, messages.append)
    final = {m.index: m for m in messages if m.kind in ("result", "error")}
    assert sorted(final) == list(range(8))  # every task ends exactly once
    assert len([m for m in messages if m.kind in ("result", "error")]) == 8
    assert final[3].kind == "error" and "ValueError: three is bad" in final[3].payload
    assert final[5].kind == "error" and final[5].payload == "worker process died (signal 9)"
    for i in (0, 1, 2, 4, 6, 7):
        assert final[i].kind == "result" and final[i].payload[0] == i * i
    pids = {final[i].payload[1] for i in (0, 1, 2, 4, 6, 7)}
    assert os.getpid() not in pids and len(pids) >= 2  # ran in worker processes
    started = [m.index for m in messages if m.kind == "started"]
    assert sorted(started) == list(range(8))
    assert {m.payload for m in messages if m.kind == "progress"} >= {("working", 0)}


def sleepy(x, progress):
    t0 = time.time()
    time.sleep(0.5)
    return os.getpid(), t0, time.time()


def test_two_workers_run_at_once():
    messages = []
    run_pool(sleepy, list(range(4)), 2, messages.append)
    out = sorted(m.payload for m in messages if m.kind == "result")
    assert len({pid for pid, _, _ in out}) == 2
    # tasks of different workers overlap in time
    a = [iv for iv in out if iv[0] == out[0][0]]
    b = [iv for iv in out if iv[0] != out[0][0]]
    assert any(s1 < e2 and s2 < e1 for _, s1, e1 in a for _, s2, e2 in b)


def fails_in_its_own_words(x, progress):
    """A task that reports its failure with a text of its own (the run service's error)."""
    raise TaskFailed(f"ValueError: run {x} broke")


def test_a_task_failed_in_its_own_words_is_reported_verbatim():
    messages = []
    run_pool(fails_in_its_own_words, [7], 1, messages.append)
    errors = [m.payload for m in messages if m.kind == "error"]
    assert errors == ["ValueError: run 7 broke"]  # no type prefix, no location appended


def touch(path, progress):
    """A task that leaves a mark the moment a worker begins it."""
    Path(path).touch()
    time.sleep(5)


def test_an_interrupt_at_a_tasks_start_leaves_no_task_begun_unreported(tmp_path):
    # the batch requeues the runs reported started when it is interrupted: a worker must never
    # begin a task the parent had not reported (that run stayed `running` for ever)
    marks = [tmp_path / f"{i}" for i in range(2)]

    def on_message(m):
        if m.kind == "started" and m.index == 1:
            time.sleep(1.0)  # time enough for a worker holding the task to begin it
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_pool(touch, [str(p) for p in marks], 2, on_message)
    assert not marks[1].exists()
