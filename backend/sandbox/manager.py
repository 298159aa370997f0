"""The one way the API reads untrusted bytes: a separate, limited process per upload.

Each upload (an estimate in any format, a floorplan with its files) is parsed by a process
forked for it from a warm zygote (`python -m backend.sandbox.child`, its parsers loaded once),
in a temporary folder of its own, with an allow-listed environment (no database or broker
URL, no secret key), hard rlimits it sets on itself first (address space, CPU seconds, file
size, open files), a wall-clock deadline and a byte quota on its folder enforced from here
(its whole session killed past either). There are `sandbox_workers` zygotes per API process,
each serving one upload at a time: the pool is bounded, an upload waits for a free one. The
API gets back a validated, typed result or a one-line reason that names no server path.
"""

from __future__ import annotations

import concurrent.futures as cf
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
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from fastapi import HTTPException, status

from backend.core.config import Settings
from worker.errors import InputError

if TYPE_CHECKING:
    from fastapi import FastAPI

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
    """What a sandbox returned: the task's facts and, for an estimate, its (N, 4) samples;
    for a floorplan, its bytes (`worker.world.floorplan`)."""

    facts: dict[str, Any]
    samples: np.ndarray | None = None
    blob: bytes | None = None


@dataclass(frozen=True)
class Limits:
    """What one task's process may use, and the settings that say so (in its messages)."""

    memory_mb: int  # [MiB] address space
    cpu_s: int  # [s] CPU time
    wall_s: float  # [s] wall time
    temp_mb: int  # [MiB] its temporary folder (and any one file)
    kind: str  # "sandbox" (reading uploads) or "analysis" (worlds, predictions): the
    # settings' prefix and which parsers its processes load
    verb: str  # what the messages say it took too much to do

    @property
    def done(self) -> str:
        """What the messages say could not be done."""
        return "analysed" if self.kind == "analysis" else "read"

    @classmethod
    def of(cls, settings: Settings, kind: str = "sandbox") -> Limits:
        s = settings
        if kind == "analysis":  # its folder holds a floorplan's bits too (1 a pixel)
            temp = s.sandbox_temp_mb + -(-s.max_image_pixels // (8 * MiB)) + 1
            return cls(s.analysis_memory_mb, s.analysis_cpu_s, s.analysis_wall_s, temp, kind,
                       "to analyse")  # fmt: skip
        return cls(s.sandbox_memory_mb, s.sandbox_cpu_s, s.sandbox_wall_s, s.sandbox_temp_mb,
                   kind, "to read")  # fmt: skip

    def over(self, what: str, limit: str, setting: str) -> str:
        """`what` `limit` `verb` (setting ..., environment ...)."""
        name = f"{self.kind}_{setting}" if setting != "temp_mb" else "sandbox_temp_mb"
        env = Settings.model_fields[name].alias
        return f"{what} {limit} {self.verb} (setting {name}, environment {env})"


class Zygote:
    """One warm parser process (`backend.sandbox.child`) serving one task at a time."""

    def __init__(self, root: Path | None, kind: str = "sandbox"):
        env = {k: os.environ[k] for k in PASS_ENV if k in os.environ}
        env.update({k: "1" for k in SINGLE_THREAD})
        env.update(PATH="/usr/bin:/bin", HOME=tempfile.gettempdir())
        # the folder its warm-up writes its tiny inputs to: made and removed here, since the
        # process may be killed in the middle of its warm-up (a server stopped at once)
        self.warm = Path(tempfile.mkdtemp(prefix="mapqual-warm-", dir=root))
        self.proc = subprocess.Popen(
            [sys.executable, "-P", "-m", "backend.sandbox.child", kind, str(self.warm)],
            cwd=root, env=env,
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
        shutil.rmtree(self.warm, ignore_errors=True)


class Sandbox:
    """`workers` warm parser processes (`settings.sandbox_workers` for uploads); a task
    waits for a free one."""

    def __init__(self, settings: Settings, limits: Limits | None = None, workers: int = 0):
        self.settings = settings
        self.lim = limits or Limits.of(settings)
        self._free: queue.LifoQueue[Zygote | None] = queue.LifoQueue()  # the warmest first
        for _ in range(workers or settings.sandbox_workers):
            self._free.put(None)  # started on first use (or by `start`)

    def _zygote(self) -> Zygote:
        return Zygote(self.settings.sandbox_dir, self.lim.kind)

    def start(self) -> None:
        """Start the idle parser processes now (an API's start-up), not at the first upload."""
        for z in self._drain():
            if z is None or z.proc.poll() is not None:
                with contextlib.suppress(OSError):
                    z = self._zygote()
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
                z = self._zygote()
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
        lim = self.lim
        return {
            "memory_mb": lim.memory_mb, "cpu_s": lim.cpu_s, "temp_mb": lim.temp_mb,
            "open_files": OPEN_FILES,
        }  # fmt: skip

    def run(self, task: str, files: dict[str, bytes], label: str = "", **args: Any) -> Parsed:
        """Parse `files` (name -> bytes; names already checked as plain file names) with
        `task` (estimate: file, topic; floorplan: file, resolution, max_pixels; world and
        predict: file, max_pixels (and slam)); `label` names the upload in messages (default:
        `file`). InputError (a 400) or ImageTooLarge (413) with one line; 503 when every
        parser stays busy."""
        z = self._take(QUEUE_WAITS * self.lim.wall_s)
        healthy = False  # a parser that answered serves the next task, whatever it answered
        try:
            with self._folder(task, files, args) as work:
                failure, healthy = self._serve(z, work)
                return self._result(work, failure, label or args.get("file", ""))
        finally:
            if not healthy:
                z.stop()
            self._free.put(z if healthy else None)

    @contextlib.contextmanager
    def _folder(self, task: str, files: dict[str, bytes], args: dict[str, Any]) -> Iterator[Path]:
        """A task's folder (`in/` the files, `out/`, `tmp/`, request.json), removed after."""
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
            yield work
        finally:  # off the answer's path: removing four folders takes ~15 ms on a busy disk
            _REMOVER.submit(shutil.rmtree, work, ignore_errors=True)

    def _serve(self, z: Zygote, work: Path) -> tuple[str | None, bool]:
        """Hand `work` to the zygote and watch its child: (what ended it early, or None;
        whether the zygote can serve again)."""
        if not z.ready:
            z.ready = z.line(STARTUP_S) is not None  # loading the parsers: a few seconds
            shutil.rmtree(z.warm, ignore_errors=True)
            if not z.ready:
                return f"could not be {self.lim.done} (no parser process started)", False
        z.send(work)
        started = z.line(STARTUP_S)
        if started is None or not isinstance(started.get("pid"), int):
            return f"could not be {self.lim.done} (no parser process started)", False
        pid = started["pid"]
        lim = self.lim
        deadline = time.monotonic() + lim.wall_s
        disk = lim.over("needs more than", f"{lim.temp_mb} MiB of disk", "temp_mb")
        failure = None
        while (done := z.line(POLL_S)) is None:
            if z.proc.poll() is not None:
                return f"could not be {self.lim.done} (its parser stopped unexpectedly)", False
            if time.monotonic() > deadline:
                failure = lim.over("took more than", f"{lim.wall_s:g} s", "wall_s")
            elif folder_bytes(work) > lim.temp_mb * MiB:
                failure = disk
            if failure is not None:
                _kill(pid)
                done = z.line(STARTUP_S)
                break
        code = None if done is None else done.get("status")
        cpu = done.get("cpu_s") if done is not None else None
        # SIGXCPU at the limit, or SIGKILL (soft = hard); a SIGKILL from elsewhere is no CPU's
        on_cpu = code == -signal.SIGXCPU or (
            code == -signal.SIGKILL and isinstance(cpu, (int, float)) and cpu >= lim.cpu_s - 0.5
        )
        if failure is None and on_cpu:
            failure = lim.over("took more than", f"{lim.cpu_s} s of CPU", "cpu_s")
        if failure is None and code == -signal.SIGXFSZ:
            failure = disk
        return failure, done is not None

    def _result(self, work: Path, failure: str | None, name: str) -> Parsed:
        from worker.world.image_io import ImageTooLarge

        if failure is not None:
            raise InputError(f"{name}: {failure}")
        out = _read_json(work / "out" / "result.json")
        if out is None:
            raise InputError(
                f"{name}: could not be {self.lim.done} (its parser stopped unexpectedly)"
            )
        if not out.get("ok"):
            kind = out.get("kind")
            if kind == "memory":
                mb = f"{self.lim.memory_mb} MiB of memory"
                raise InputError(f"{name}: {self.lim.over('needs more than', mb, 'memory_mb')}")
            reason = scrub_paths(str(out.get("error", ""))[:500], work) or "cannot be read"
            raise (ImageTooLarge if kind == "too_large" else InputError)(reason)
        samples, blob = None, None
        bin_ = work / "out" / "result.bin"
        if bin_.is_file() and bin_.stat().st_size <= RESULT_MAX:
            blob = bin_.read_bytes()
        npy = work / "out" / "trajectory.npy"
        if npy.is_file() and npy.stat().st_size <= RESULT_MAX:
            samples = np.load(npy, allow_pickle=False)
            if samples.dtype != np.float64 or samples.ndim != 2 or samples.shape[1] != 4:
                raise InputError(f"{name}: could not be {self.lim.done} (a malformed result)")
        return Parsed({k: v for k, v in out.items() if k != "ok"}, samples, blob)


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


_REMOVER = cf.ThreadPoolExecutor(1, thread_name_prefix="mapqual-sandbox-rm")
_MAKING = threading.Lock()
_SHARED: dict[tuple[int, str], tuple[Settings, Sandbox]] = {}


def shared_sandbox(settings: Settings, kind: str = "sandbox") -> Sandbox:
    """The process's sandbox for these settings (one pool per settings object, an app's, and
    kind: "sandbox" reads uploads, "analysis" analyses worlds with `world_workers`)."""
    with _MAKING:
        found = _SHARED.get((id(settings), kind))
        if found is None or found[0] is not settings:
            workers = settings.world_workers if kind == "analysis" else 0
            box = Sandbox(settings, Limits.of(settings, kind), workers)
            found = _SHARED[(id(settings), kind)] = (settings, box)
        return found[1]


def sandbox(app: FastAPI) -> Sandbox:
    """The app's sandbox (made on first use, with the app's settings)."""
    return shared_sandbox(app.state.settings)
