"""Compile the numba kernels in a process of their own, once for each version of the sources.

numba compiles a kernel at its first call, and most of what the compiler allocates stays in
the process that compiled it. A `mapqual run` of office_a for 60 s simulated, one SLAM
thread, peaked at 704 MiB with an empty cache against 465 MiB with the kernels in it, and
ended 200 MiB higher (2026-12-06, docs/results/mapqual-run-memory.md). A run's peak comes at
its end, so that memory adds to it: a user's first run on a large plan after an install or an
upgrade, and every Celery worker process for as long as it lives.

`warm_kernels(algorithm)` runs a short run (60 s simulated of that algorithm on a small
generated hospital wing) in a child process, `python -m worker.kernel_warmup ALGORITHM`. The
child fills numba's on-disk cache (NUMBA_CACHE_DIR, which `worker/__init__` points at a folder
named after the sources) and exits; the caller's kernels then load from the cache. A marker
file in the cache folder, named after the algorithm, the sources, numba and Python, says it
was done; a lock keeps the processes of a batch's pool from warming at once. Kernels the short
run does not reach compile in the caller as before. When the cache cannot be written, the
child fails or MAPQUAL_WARM_KERNELS=0, the caller compiles in-process as before, the same
kernels with the same results.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import logging
import os
import subprocess
import sys
from pathlib import Path

log = logging.getLogger(__name__)

ENV_SWITCH = "MAPQUAL_WARM_KERNELS"  # "0": never warm in a child
_ENV_CHILD = "MAPQUAL_WARMING_KERNELS"  # set in the child: its own run must not warm again
TIMEOUT_S = 900.0  # [s] of wall time for the child (a cold compile takes about one minute)


def cache_folder() -> Path | None:
    """numba's on-disk cache folder, if it is set and can be written (else None)."""
    raw = os.environ.get("NUMBA_CACHE_DIR", "").strip()
    if not raw:
        return None
    folder = Path(raw)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return folder if os.access(folder, os.W_OK) else None


def marker_name(algorithm: str) -> str:
    """The marker's file name: the algorithm, the package's sources, numba and Python."""
    return f"warmed-{algorithm}-{_version_key()}"


@functools.cache
def _version_key() -> str:
    """The sources as this process loaded them (their paths, sizes and times, as the cache
    folder's name), numba and Python: read once a process, not once a run."""
    import numba

    from worker import numba_cache_dir

    sources = numba_cache_dir(Path(__file__).resolve().parent).name
    what = f"{sources}\0{numba.__version__}\0{sys.version}\0{sys.executable}"
    return hashlib.blake2b(what.encode(), digest_size=8).hexdigest()


def warm_algorithm(algorithm: str) -> str:
    """The algorithm the child runs: a third-party SLAM's run warms the exploration's
    kernels through the oracle (the child has no program to call)."""
    return "oracle" if algorithm == "external" else algorithm


def warm_kernels(algorithm: str = "rbpf", *, timeout_s: float = TIMEOUT_S, announce=None) -> bool:
    """Fill numba's cache for a run of `algorithm` in a child process, unless done already;
    `announce()` (optional) is called before the child starts. True when the cache holds the
    warm run's kernels (now or before); False when it was not done (switched off, no writable
    cache, the child failed), the caller compiling in-process."""
    if os.environ.get(ENV_SWITCH, "").strip() == "0" or os.environ.get(_ENV_CHILD):
        return False
    folder = cache_folder()
    if folder is None:
        return False
    algorithm = warm_algorithm(algorithm)
    marker = folder / marker_name(algorithm)
    if marker.exists():
        return True
    with _locked(folder / "warm.lock"):
        if marker.exists():  # another process warmed it while this one waited
            return True
        if announce is not None:
            announce()
        if not _run_child(algorithm, timeout_s):
            return False
        marker.write_text("the kernels of a warm-up run are in this cache\n")
    return True


@contextlib.contextmanager
def _locked(path: Path):
    try:
        import fcntl
    except ImportError:  # no flock (Windows): processes may warm at once, each correctly
        yield
        return
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


def _run_child(algorithm: str, timeout_s: float) -> bool:
    env = {**os.environ, _ENV_CHILD: "1"}
    cmd = [sys.executable, "-m", "worker.kernel_warmup", algorithm]
    log.info("compiling the kernels for %s in a child process (once per version)", algorithm)
    try:
        out = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout_s)
    except (OSError, subprocess.TimeoutExpired) as exc:
        log.warning("kernels not compiled in a child (%s); compiling in this process", exc)
        return False
    if out.returncode != 0:
        tail = out.stderr.strip().splitlines()[-1:] or ["no message"]
        log.warning("kernels not compiled in a child (exit %s: %s); compiling in this process",
                    out.returncode, tail[0])  # fmt: skip
        return False
    return True
