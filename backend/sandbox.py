"""The one way the API reads untrusted bytes: a separate, limited process per upload.

Each upload (an estimate in any format, a floorplan with its files) is parsed by a process
forked for it from a warm zygote (`python -m backend.sandbox_child`, its parsers loaded once),
in a temporary folder of its own, with an allow-listed environment (no database or broker
URL, no secret key), hard rlimits it sets on itself first (address space, CPU seconds, file
size, open files), a wall-clock deadline and a byte quota on its folder enforced from here
(its whole session killed past either). There are `sandbox_workers` zygotes per API process,
each serving one upload at a time: the pool is bounded, an upload waits for a free one. The
API gets back a validated, typed result or a one-line reason that names no server path.
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import re
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from fastapi import HTTPException, status

from backend.core.config import Settings
from worker.errors import InputError

MiB = 1 << 20
OPEN_FILES = 64  # descriptors a sandbox may hold: the upload, a bag's few files, Python's own
POLL_S = 0.05  # [s] between looks at the process, its deadline and its folder's size
QUEUE_WAITS = 3  # an upload waits for a free parser up to this many wall times, then 503
STARTUP_S = 60.0  # [s] a parser process may take to load (and a fork to be reported)
RESULT_MAX = 64 * MiB  # [bytes] a result file may hold (a trajectory of 2 M poses)
# What the parser's process may know of the server's environment: nothing but the locale and
# where Python finds the project (a checkout run without installing it).
PASS_ENV = ("LANG", "LC_ALL", "PYTHONPATH")
SINGLE_THREAD = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")


@dataclass(frozen=True)
class Parsed:
    """What a sandbox returned: the task's facts and, for an estimate, its (N, 4) samples."""

    facts: dict[str, Any]
    samples: np.ndarray | None = None


class Zygote:
    """One warm parser process (`backend.sandbox_child`) serving one upload at a time."""

    def __init__(self, root: Path | None):
        env = {k: os.environ[k] for k in PASS_ENV if k in os.environ}
        env.update({k: "1" for k in SINGLE_THREAD})
        env.update(PATH="/usr/bin:/bin", HOME=tempfile.gettempdir())
        self.proc = subprocess.Popen(
            [sys.executable, "-P", "-m", "backend.sandbox_child"], cwd=root, env=env,
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            close_fds=True, start_new_session=True,
        )  # fmt: skip
        self._buf = b""
        self.ready = False  # it said so once it loaded the parsers

    def line(self, timeout: float) -> dict[str, Any] | None:
        """The next line it writes, within `timeout` [s] (None: none came, or it died)."""
        fd = self.proc.stdout.fileno()  # type: ignore[union-attr]
        end = time.monotonic() + timeout
        while b"\n" not in self._buf:
            left = end - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return None
            piece = os.read(fd, 4096)
            if not piece:
                return None
            self._buf += piece
        raw, self._buf = self._buf.split(b"\n", 1)
        try:
            out = json.loads(raw)
        except ValueError:
            return None
        return out if isinstance(out, dict) else None

    def send(self, work: Path) -> None:
        self.proc.stdin.write(json.dumps({"work": str(work)}).encode() + b"\n")  # type: ignore[union-attr]
        self.proc.stdin.flush()  # type: ignore[union-attr]

    def stop(self) -> None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait()


class Sandbox:
    """`settings.sandbox_workers` warm parser processes; an upload waits for a free one."""

    def __init__(self, settings: Settings):
        self.settings = settings
        self._free: queue.LifoQueue[Zygote | None] = queue.LifoQueue()  # the warmest first
        for _ in range(settings.sandbox_workers):
            self._free.put(None)  # started on first use (or by `start`)

    def start(self) -> None:
        """Start the idle parser processes now (an API's start-up), not at the first upload."""
        for z in self._drain():
            if z is None or z.proc.poll() is not None:
                with contextlib.suppress(OSError):
                    z = Zygote(self.settings.sandbox_dir)
            self._free.put(z)

    def _drain(self) -> list[Zygote | None]:
        """Take every idle slot out of the pool (the caller puts one back for each)."""
        held = []
        while True:
            try:
                held.append(self._free.get_nowait())
            except queue.Empty:
                return held

    def _take(self, timeout: float) -> Zygote | None:
        try:
            z = self._free.get(timeout=timeout) if timeout > 0 else self._free.get_nowait()
        except queue.Empty:
            raise HTTPException(
                status.HTTP_503_SERVICE_UNAVAILABLE,
                "every upload parser is busy; try again shortly (setting sandbox_workers, "
                "environment MAPQUAL_SANDBOX_WORKERS)",
                headers={"Retry-After": "5"},
            ) from None
        if z is None or z.proc.poll() is not None:
            try:
                z = Zygote(self.settings.sandbox_dir)
            except OSError:
                self._free.put(None)
                raise
        return z

    def shutdown(self) -> None:
        """Stop the idle parser processes (those at work stop when their upload is done);
        the next upload starts new ones."""
        for z in self._drain():
            if z is not None:
                z.stop()
            self._free.put(None)

    def limits(self) -> dict[str, int]:
        s = self.settings
        return {
            "memory_mb": s.sandbox_memory_mb, "cpu_s": s.sandbox_cpu_s,
            "temp_mb": s.sandbox_temp_mb, "open_files": OPEN_FILES,
        }  # fmt: skip

    def run(self, task: str, files: dict[str, bytes], **args: Any) -> Parsed:
        """Parse `files` (name -> bytes; names already checked as plain file names) with
        `task` (estimate: file, topic; floorplan: file, resolution, max_pixels). InputError
        (a 400) or ImageTooLarge (413) with one line; 503 when every parser stays busy."""
        z = self._take(QUEUE_WAITS * self.settings.sandbox_wall_s)
        healthy = False
        try:
            parsed, healthy = self._run(z, task, files, args)
            return parsed
        finally:
            if not healthy:
                z.stop()
            self._free.put(z if healthy else None)

    def _run(
        self, z: Zygote, task: str, files: dict[str, bytes], args: dict[str, Any]
    ) -> tuple[Parsed, bool]:
        root = self.settings.sandbox_dir
        if root is not None:
            root.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix="mapqual-sandbox-", dir=root))
        try:
            for sub in ("in", "out", "tmp"):
                (work / sub).mkdir()
            for name, data in files.items():
                (work / "in" / name).write_bytes(data)
            unpacked = self.settings.upload_unpacked_mb * MiB
            request = {"task": task, "limits": self.limits(), "unpacked_bytes": unpacked, **args}
            (work / "request.json").write_text(json.dumps(request))
            failure, healthy = self._serve(z, work)
            return self._result(work, failure, args.get("file", "")), healthy
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _serve(self, z: Zygote, work: Path) -> tuple[str | None, bool]:
        """Hand `work` to the zygote and watch its child: (what ended it early, or None;
        whether the zygote can serve again)."""
        if not z.ready:
            z.ready = z.line(STARTUP_S) is not None  # loading the parsers: a few seconds
            if not z.ready:
                return "could not be read (no parser process started)", False
        z.send(work)
        started = z.line(STARTUP_S)
        if started is None or not isinstance(started.get("pid"), int):
            return "could not be read (no parser process started)", False
        pid = started["pid"]
        s = self.settings
        deadline = time.monotonic() + s.sandbox_wall_s
        failure = None
        while (done := z.line(POLL_S)) is None:
            if z.proc.poll() is not None:
                return "could not be read (its parser stopped unexpectedly)", False
            if time.monotonic() > deadline:
                failure = _over("took more than", f"{s.sandbox_wall_s:g} s", "sandbox_wall_s")
            elif folder_bytes(work) > s.sandbox_temp_mb * MiB:
                failure = _over(
                    "needs more than", f"{s.sandbox_temp_mb} MiB of disk", "sandbox_temp_mb"
                )  # noqa: E501
            if failure is not None:
                _kill(pid)
                done = z.line(STARTUP_S)
                break
        code = None if done is None else done.get("status")
        if failure is None and code in (-signal.SIGXCPU, -signal.SIGKILL):
            failure = _over("took more than", f"{s.sandbox_cpu_s} s of CPU", "sandbox_cpu_s")
        if failure is None and code == -signal.SIGXFSZ:
            failure = _over(
                "needs more than", f"{s.sandbox_temp_mb} MiB of disk", "sandbox_temp_mb"
            )  # noqa: E501
        return failure, done is not None

    def _result(self, work: Path, failure: str | None, name: str) -> Parsed:
        from worker.world.image_io import ImageTooLarge

        if failure is not None:
            raise InputError(f"{name}: {failure}")
        out = _read_json(work / "out" / "result.json")
        if out is None:
            raise InputError(f"{name}: could not be read (its parser stopped unexpectedly)")
        if not out.get("ok"):
            kind = out.get("kind")
            if kind == "memory":
                mb = f"{self.settings.sandbox_memory_mb} MiB of memory"
                raise InputError(f"{name}: {_over('needs more than', mb, 'sandbox_memory_mb')}")
            reason = scrub_paths(str(out.get("error", ""))[:500], work) or "cannot be read"
            raise (ImageTooLarge if kind == "too_large" else InputError)(reason)
        samples = None
        npy = work / "out" / "trajectory.npy"
        if npy.is_file() and npy.stat().st_size <= RESULT_MAX:
            samples = np.load(npy, allow_pickle=False)
            if samples.dtype != np.float64 or samples.ndim != 2 or samples.shape[1] != 4:
                raise InputError(f"{name}: could not be read (a malformed result)")
        return Parsed({k: v for k, v in out.items() if k != "ok"}, samples)


def _over(what: str, limit: str, setting: str) -> str:
    env = Settings.model_fields[setting].alias
    return f"{what} {limit} to read (setting {setting}, environment {env})"


def _kill(pid: int) -> None:
    """The child and its session (it called setsid first thing; if it had not yet, itself)."""
    for kill in (os.killpg, os.kill):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            kill(pid, signal.SIGKILL)


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        if path.stat().st_size > MiB:
            return None
        out = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return out if isinstance(out, dict) else None


def folder_bytes(folder: Path) -> int:
    """Bytes the files under `folder` take on disk (allocated blocks: a sparse file counts
    for what it holds)."""
    total = 0
    stack = [folder]
    while stack:
        try:
            with os.scandir(stack.pop()) as it:
                for entry in it:
                    if entry.is_dir(follow_symlinks=False):
                        stack.append(Path(entry.path))
                    else:
                        total += entry.stat(follow_symlinks=False).st_blocks * 512
        except OSError:
            continue
    return total


def scrub_paths(message: str, *folders: Path) -> str:
    """`message` without the server's paths: the sandbox's folder (and its `in/`, where the
    uploads lie) dropped, other absolute paths under it or the system's temporary folder
    shortened to their last part."""
    roots = {str(tempfile.gettempdir())}
    for f in folders:
        for p in (f, f.resolve()):
            message = message.replace(f"{p}/in/", "").replace(f"{p}/", "")
            roots.add(str(p))
    for root in sorted(roots, key=len, reverse=True):
        message = re.sub(re.escape(root) + r"[^\s'\":]*", lambda m: _last(m.group(0)), message)
    return message


def server_folders(settings: Settings) -> list[Path]:
    """The folders whose paths an answer must not show."""
    out = [settings.runs_dir.absolute()]
    if settings.sandbox_dir is not None:
        out.append(settings.sandbox_dir.absolute())
    return out


def _last(path: str) -> str:
    return Path(path).name or "."


_MAKING = threading.Lock()
_SHARED: dict[int, tuple[Settings, Sandbox]] = {}


def shared_sandbox(settings: Settings) -> Sandbox:
    """The process's sandbox for these settings (one pool per settings object: an app's)."""
    with _MAKING:
        found = _SHARED.get(id(settings))
        if found is None or found[0] is not settings:
            found = _SHARED[id(settings)] = (settings, Sandbox(settings))
        return found[1]


def sandbox(app: Any) -> Sandbox:
    """The app's sandbox (made on first use, with the app's settings)."""
    return shared_sandbox(app.state.settings)
