"""The external program as a child process: frames over its stdin / stdout with a deadline,
its stderr kept in a file for the failure message, and no zombie or orphan left behind (its
whole tree ends with it, see `confine`), within its memory and CPU limits."""

from __future__ import annotations

import contextlib
import fcntl
import os
import select
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Sequence
from typing import Any

from worker.slam.external.confine import (
    become_subreaper,
    children_of,
    end_tree,
    preexec,
    program_env,
)
from worker.slam.external.protocol import HEADER, MAX_FRAME, ProtocolError, unpack

PIPE_BYTES = 1 << 20  # [bytes] pipe buffers asked for (Linux's default maximum)


class ChildGone(RuntimeError):
    """The program exited, closed its pipes or missed a deadline (the message says which)."""


# The programs this process runs now: never taken for another program's orphans.
_LIVE: set[int] = set()
_LIVE_LOCK = threading.Lock()


def _grow_pipe(fd: int, size: int = PIPE_BYTES) -> None:
    """Linux: make the pipe's buffer `size` bytes (at most /proc/sys/fs/pipe-max-size)."""
    with contextlib.suppress(OSError, AttributeError):
        fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, size)


class ChildProcess:
    """A started program; `send` and `recv` take an absolute `time.monotonic()` deadline."""

    def __init__(
        self,
        command: Sequence[str],
        env: dict[str, str] | None = None,
        memory_mb: int = 0,
        cpu_s: int = 0,
    ):
        """`env`: the program's environment (None: the allow-listed part of ours);
        `memory_mb`, `cpu_s`: its address space and CPU time limits (0: none)."""
        # a file, not a pipe: a chatty program never blocks on it, and no thread drains it
        self._stderr = tempfile.TemporaryFile()  # noqa: SIM115 - open for the program's life
        self._subreaper = become_subreaper()
        self._before = children_of([os.getpid()]) if self._subreaper else set()
        try:
            self.proc = subprocess.Popen(
                list(command), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                stderr=self._stderr, bufsize=0, close_fds=True, start_new_session=True,
                preexec_fn=preexec(memory_mb, cpu_s),
                env=program_env() if env is None else env,
            )  # fmt: skip
        except OSError as exc:
            self._stderr.close()
            raise ChildGone(f"cannot start {command[0]!r}: {exc.strerror or exc}") from None
        with _LIVE_LOCK:
            _LIVE.add(self.proc.pid)
        self._out = self.proc.stdout.fileno()  # type: ignore[union-attr]
        self._in = self.proc.stdin.fileno()  # type: ignore[union-attr]
        os.set_blocking(self._out, False)
        os.set_blocking(self._in, False)
        for fd in (self._out, self._in):  # a map in a few wake-ups, not one per 64 KiB
            _grow_pipe(fd)
        self._buf = bytearray()
        self._chunk = bytearray(PIPE_BYTES)  # what one read() takes
        self._chunk_view = memoryview(self._chunk)
        self._pollers: dict[tuple[int, int], select.poll] = {}  # (fd, event): made once
        self.closed = False
        self._tail = ""  # the stderr tail, kept when the process is closed

    @property
    def pid(self) -> int:
        return self.proc.pid

    def send(self, data: bytes, deadline: float) -> None:
        """Write all of `data` before `deadline`, or ChildGone."""
        view = memoryview(data)
        while view:
            try:
                n = os.write(self._in, view)
            except BlockingIOError:
                n = 0
            except (BrokenPipeError, ConnectionResetError):
                raise ChildGone(self._gone("closed its input")) from None
            view = view[n:]
            if view and not self._wait(self._in, select.POLLOUT, deadline):
                raise ChildGone(self._late(deadline, "to read its input"))

    def recv(self, deadline: float) -> bytes:
        """The payload of the next frame, read before `deadline`, or ChildGone."""
        n = self._frame(deadline)
        payload = bytes(memoryview(self._buf)[HEADER.size : HEADER.size + n])
        del self._buf[: HEADER.size + n]
        return payload

    def recv_message(self, deadline: float) -> dict[str, Any]:
        """The message of the next frame (see `recv`), decoded where it lies in the buffer."""
        n = self._frame(deadline)
        with memoryview(self._buf) as view:
            message = unpack(view[HEADER.size : HEADER.size + n])
        del self._buf[: HEADER.size + n]
        return message

    def _frame(self, deadline: float) -> int:
        """Buffer the next whole frame; its payload's length."""
        size = HEADER.size
        while len(self._buf) < size:
            self._fill(deadline)
        (n,) = HEADER.unpack_from(self._buf)
        if n > MAX_FRAME:
            raise ProtocolError(f"a frame of {n} bytes announced (more than {MAX_FRAME})")
        while len(self._buf) < size + n:
            self._fill(deadline)
        return n

    def _fill(self, deadline: float) -> None:
        if not self._wait(self._out, select.POLLIN, deadline):
            raise ChildGone(self._late(deadline, "to answer"))
        try:
            n = os.readv(self._out, [self._chunk])  # into a buffer made once: no allocation
        except BlockingIOError:
            return
        if not n:
            raise ChildGone(self._gone("closed its output"))
        self._buf += self._chunk_view[:n]

    def _wait(self, fd: int, event: int, deadline: float) -> bool:
        """Whether `fd` is ready (or hung up) before the deadline."""
        poller = self._pollers.get((fd, event))
        if poller is None:
            poller = self._pollers[(fd, event)] = select.poll()
            poller.register(fd, event | select.POLLHUP | select.POLLERR)
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                return False
            if poller.poll(max(1, int(left * 1000))):
                return True

    def _gone(self, what: str) -> str:
        try:
            code = self.proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            return f"the program {what}"
        how = f"was killed by signal {-code}" if code < 0 else f"exited with code {code}"
        return f"the program {how}"

    def _late(self, deadline: float, what: str) -> str:
        if self.proc.poll() is not None:
            return self._gone("exited")
        return f"the program took too long {what} (time-out)"

    def stderr_tail(self, max_bytes: int = 2000, max_lines: int = 12) -> str:
        """The last lines the program wrote to stderr (empty when it wrote none)."""
        if self.closed:
            return self._tail
        try:
            self._stderr.seek(0, os.SEEK_END)
            size = self._stderr.tell()
            self._stderr.seek(max(0, size - max_bytes))
            text = self._stderr.read().decode("utf-8", errors="replace")
        except (OSError, ValueError):
            return ""
        return "\n".join(text.strip().splitlines()[-max_lines:])

    def close(self, grace_s: float) -> int | None:
        """Let the program exit within `grace_s` [s] (stdin closed), else kill its process
        group; always reaped. Its exit code (negative: a signal)."""
        if self.closed:
            return self.proc.returncode
        for pipe in (self.proc.stdin, self.proc.stdout):
            with contextlib.suppress(OSError):
                pipe.close()  # type: ignore[union-attr]
        try:
            self.proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            self._kill_group()
        self._kill_group(signal.SIGKILL, quiet=True)  # whatever it started and left behind
        end_tree(self.proc.pid, self._orphans)  # and what left its process group
        with _LIVE_LOCK:
            _LIVE.discard(self.proc.pid)
        self._tail = self.stderr_tail()
        self.closed = True
        self._stderr.close()
        return self.proc.returncode

    def _orphans(self) -> set[int]:
        """Children of this process that it did not start itself: descendants of the program
        that re-parented here (we are their subreaper) after their parent ended."""
        if not self._subreaper:
            return set()
        with _LIVE_LOCK:
            live = set(_LIVE)
        return children_of([os.getpid()]) - self._before - live - {self.proc.pid}

    def _kill_group(self, sig: int = signal.SIGKILL, quiet: bool = False) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.proc.pid, sig)
        if not quiet:
            self.proc.wait()
