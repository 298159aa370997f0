"""A process pool that survives its tasks: an exception, or a worker process dying, fails one
task and the rest carry on (concurrent.futures would break the whole pool on a dead worker)."""

from __future__ import annotations

import multiprocessing as mp
import os
import queue
import signal
import time
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

POLL_S = 0.5  # [s] how often the parent checks its workers are alive


@dataclass(frozen=True)
class PoolMessage:
    """What the pool reports: a task `started`, its `progress`, its `result` or its `error`."""

    kind: str  # started | progress | result | error
    index: int  # the task's index in the submitted sequence
    payload: Any = None  # progress data, the result, or the error text


class ParentGone(SystemExit):
    """Raised inside a worker whose parent died: the run stops instead of running orphaned."""


def _child(fn: Callable, tasks: Any, results: Any, parent_pid: int) -> None:
    """A worker process: run tasks until told to stop or until the parent is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides on Ctrl-C

    def parent_alive() -> bool:
        return os.getppid() == parent_pid

    while parent_alive():
        try:
            item = tasks.get(timeout=1.0)
        except queue.Empty:
            continue
        if item is None:
            return
        index, arg = item

        def progress(payload: Any, index: int = index) -> None:
            if not parent_alive():
                raise ParentGone(1)
            results.put(("progress", index, payload))

        try:
            out = fn(arg, progress)
        except ParentGone:
            return
        except BaseException as exc:  # noqa: BLE001 - any failure fails this task only
            last = traceback.extract_tb(exc.__traceback__)[-1:]
            where = f" (at {last[0].filename}:{last[0].lineno})" if last else ""
            results.put(("error", index, f"{type(exc).__name__}: {exc}{where}"))
            continue
        results.put(("result", index, out))


class _Slot:
    """One worker process, its private task queue, and the task it holds."""

    def __init__(self, ctx: Any, fn: Callable, results: Any):
        self.tasks = ctx.Queue()
        self.proc = ctx.Process(
            target=_child, args=(fn, self.tasks, results, os.getpid()), daemon=True
        )
        self.proc.start()
        self.index: int | None = None


def run_pool(
    fn: Callable[[Any, Callable[[Any], None]], Any],
    items: Sequence[Any],
    workers: int,
    on_message: Callable[[PoolMessage], None],
) -> None:
    """Run `fn(item, progress)` for every item in `workers` processes, reporting through
    `on_message` in this process. Blocks until all are done; on KeyboardInterrupt (or any
    error in `on_message`) the workers are terminated and the exception propagates.

    `fn` must be importable (the processes are spawned, not forked: the parent may hold
    threads, such as a progress bar's, that a fork would copy in a locked state).
    """
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    pending = deque(enumerate(items))
    slots = [_Slot(ctx, fn, results) for _ in range(max(1, min(workers, len(items))))]
    finished: set[int] = set()
    checked = time.monotonic()
    try:
        while pending or any(s.index is not None for s in slots):
            for s in slots:
                if s.index is None and pending:
                    s.index, arg = pending.popleft()
                    s.tasks.put((s.index, arg))
                    on_message(PoolMessage("started", s.index))
            try:
                kind, index, payload = results.get(timeout=POLL_S)
            except queue.Empty:
                kind = None
            if kind is not None and index not in finished:
                if kind != "progress":
                    finished.add(index)
                    for s in slots:
                        if s.index == index:
                            s.index = None
                on_message(PoolMessage(kind, index, payload))
            if time.monotonic() - checked >= POLL_S:
                checked = time.monotonic()
                _replace_dead(ctx, fn, results, slots, finished, on_message)
    finally:
        _shutdown(slots)


def _replace_dead(
    ctx: Any, fn: Callable, results: Any, slots: list[_Slot], finished: set[int], on_message
) -> None:
    """A worker that died holding a task (killed, out of memory) fails that task only."""
    for i, s in enumerate(slots):
        if s.proc.is_alive():
            continue
        if s.index is not None:
            finished.add(s.index)  # a result it sent just before dying is ignored
            code = s.proc.exitcode
            how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
            index, s.index = s.index, None
            on_message(PoolMessage("error", index, f"worker process died ({how})"))
        slots[i] = _Slot(ctx, fn, results)


def _shutdown(slots: list[_Slot]) -> None:
    for s in slots:
        if s.proc.is_alive() and s.index is None:
            s.tasks.put(None)
    for s in slots:
        if s.index is not None and s.proc.is_alive():
            s.proc.terminate()  # a run in flight is lost; its task is redone on resume
        s.proc.join(timeout=5)
        if s.proc.is_alive():
            s.proc.kill()
            s.proc.join(timeout=5)
