"""A process pool that survives its tasks: an exception, or a worker process dying, fails one
task and the rest carry on (concurrent.futures would break the whole pool on a dead worker).

Each worker talks to the parent over its own pipe. A shared multiprocessing.Queue would not
do: a worker killed while writing to it dies holding the queue's writer lock, and every other
worker then blocks forever on its next message.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import signal
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from worker.heap import release_free_heap

POLL_S = 0.5  # [s] how often the parent checks its workers are alive


@dataclass(frozen=True)
class PoolMessage:
    """What the pool reports: a task `started`, its `progress`, its `result` or its `error`."""

    kind: str  # started | progress | result | error
    index: int  # the task's index in the submitted sequence
    payload: Any = None  # progress data, the result, or the error text


class TaskFailed(Exception):
    """Raised by a task that failed with an error text of its own: sent as it is."""


class ParentGone(SystemExit):
    """Raised inside a worker whose parent died: the run stops instead of running orphaned."""


def _child(fn: Callable, conn: Connection, parent_pid: int) -> None:
    """A worker process: run tasks until told to stop or until the parent is gone."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides on Ctrl-C

    def parent_alive() -> bool:
        return os.getppid() == parent_pid

    while parent_alive():
        if not conn.poll(1.0):
            continue
        item = conn.recv()
        if item is None:
            return
        index, arg = item

        def progress(payload: Any, index: int = index) -> None:
            if not parent_alive():
                raise ParentGone(1)
            conn.send(("progress", index, payload))

        try:
            out = fn(arg, progress)
        except ParentGone:
            return
        except TaskFailed as exc:
            conn.send(("error", index, str(exc)))
            continue
        except BaseException as exc:  # noqa: BLE001 - any failure fails this task only
            last = traceback.extract_tb(exc.__traceback__)[-1:]
            where = f" (at {last[0].filename}:{last[0].lineno})" if last else ""
            conn.send(("error", index, f"{type(exc).__name__}: {exc}{where}"))
            continue
        finally:
            release_free_heap()  # a run's freed maps, back to the system before the next
        conn.send(("result", index, out))


class _Slot:
    """One worker process, its pipe, and the task it holds."""

    def __init__(self, ctx: Any, fn: Callable):
        self.conn, child_conn = ctx.Pipe(duplex=True)
        self.proc = ctx.Process(target=_child, args=(fn, child_conn, os.getpid()), daemon=True)
        self.proc.start()
        child_conn.close()
        self.index: int | None = None

    def give(self, index: int, arg: Any) -> None:
        self.index = index
        self.conn.send((index, arg))

    def died(self) -> str:
        code = self.proc.exitcode
        how = f"signal {-code}" if code is not None and code < 0 else f"exit code {code}"
        return f"worker process died ({how})"


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
    pending = deque(enumerate(items))
    slots = [_Slot(ctx, fn) for _ in range(max(1, min(workers, len(items))))]
    try:
        while pending or any(s.index is not None for s in slots):
            for s in slots:
                if s.index is None and pending:
                    index, arg = pending.popleft()
                    # reported before the worker has it: an interrupt (SIGTERM raises in the
                    # parent right after the blocking send) must find every task a worker may
                    # have begun among those reported started, and the parent prepares for a
                    # task (its folder emptied) before the worker writes there
                    on_message(PoolMessage("started", index))
                    s.give(index, arg)
            busy = {s.conn: s for s in slots if s.index is not None}
            for conn in wait(list(busy), timeout=POLL_S):
                _receive(busy[conn], on_message)
            for i, s in enumerate(slots):
                if not s.proc.is_alive():
                    _fail_dead(s, on_message)
                    slots[i] = _Slot(ctx, fn)
    finally:
        _shutdown(slots)


def _receive(slot: _Slot, on_message: Callable[[PoolMessage], None]) -> bool:
    """Pass on one message of the slot's worker; False at the end of its pipe (it died)."""
    try:
        kind, index, payload = slot.conn.recv()
    except (EOFError, OSError):
        slot.proc.join(timeout=1)  # the liveness check reports it
        return False
    if kind != "progress":
        slot.index = None
    on_message(PoolMessage(kind, index, payload))
    return True


def _fail_dead(slot: _Slot, on_message: Callable[[PoolMessage], None]) -> None:
    """A worker that died holding a task (killed, out of memory) fails that task only, once
    whatever it sent before dying has been passed on."""
    slot.proc.join(timeout=1)
    while slot.index is not None and slot.conn.poll() and _receive(slot, on_message):
        pass
    if slot.index is not None:
        index, slot.index = slot.index, None
        on_message(PoolMessage("error", index, slot.died()))
    slot.conn.close()


def _shutdown(slots: list[_Slot]) -> None:
    for s in slots:
        if s.proc.is_alive() and s.index is None:
            with contextlib.suppress(OSError):  # it may have just died
                s.conn.send(None)
    for s in slots:
        if s.index is not None and s.proc.is_alive():
            s.proc.terminate()  # a run in flight is lost; its task is redone on resume
        s.proc.join(timeout=5)
        if s.proc.is_alive():
            s.proc.kill()
            s.proc.join(timeout=5)
        s.conn.close()
