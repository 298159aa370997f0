"""What an external SLAM program may have: an allow-listed environment, memory and CPU limits,
and an end with the run for its whole process tree, descendants that left its session
included (Linux: this process becomes their subreaper, so orphans re-parent to it, not init).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import resource
import signal
import time
from collections.abc import Callable, Iterable, Mapping

_PR_SET_PDEATHSIG = 1
_PR_SET_CHILD_SUBREAPER = 36
MiB = 1 << 20

# The variables a program may see (a ROS bridge needs its workspace's); everything else, the
# database and broker URLs and the secret key above all, stays with the worker.
PASS_NAMES = {
    "PATH", "HOME", "USER", "LOGNAME", "LANG", "LANGUAGE", "TZ", "TERM", "TMPDIR",
    "LD_LIBRARY_PATH", "PYTHONPATH", "CMAKE_PREFIX_PATH", "DISPLAY",
}  # fmt: skip
PASS_PREFIXES = ("LC_", "ROS_", "AMENT_", "COLCON_", "RMW_", "CYCLONEDDS_", "FASTRTPS_")
# Never passed, whatever the lists above say (a secret named like a ROS variable).
_SECRET = re.compile(
    r"SECRET|PASSWORD|PASSWD|TOKEN|CREDENTIAL|_KEY$|DATABASE|REDIS|BROKER|^MAPQUAL_"
)


def program_env(environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """The allow-listed part of `environ` (the worker's environment by default)."""
    env = os.environ if environ is None else environ
    return {
        k: v
        for k, v in env.items()
        if (k in PASS_NAMES or k.startswith(PASS_PREFIXES)) and not _SECRET.search(k.upper())
    }


def _libc_prctl() -> Callable[..., int] | None:
    """libc's prctl, looked up in the parent (no dynamic loading between fork and exec)."""
    try:
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


PRCTL = _libc_prctl()


def become_subreaper() -> bool:
    """Linux: orphaned descendants of this process re-parent to it (so they can be found and
    ended). Whether that holds."""
    return PRCTL is not None and PRCTL(_PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) == 0


def preexec(memory_mb: int, cpu_s: int) -> Callable[[], None]:
    """What runs in the child between fork and exec: die with the worker, and the limits."""
    limits = []
    if memory_mb > 0:
        limits.append((resource.RLIMIT_AS, memory_mb * MiB))
    if cpu_s > 0:
        limits.append((resource.RLIMIT_CPU, cpu_s))
    limits.append((resource.RLIMIT_CORE, 0))

    def run() -> None:  # pragma: no cover - runs in the child
        if PRCTL is not None:
            PRCTL(_PR_SET_PDEATHSIG, signal.SIGKILL)
        for what, value in limits:
            resource.setrlimit(what, (value, value))

    return run


def children_of(pids: Iterable[int]) -> set[int]:
    """The direct children of `pids` (Linux /proc; empty elsewhere)."""
    wanted = set(pids)
    found: set[int] = set()
    with contextlib.suppress(OSError):
        for entry in os.scandir("/proc"):
            if not entry.name.isdigit():
                continue
            try:
                with open(f"/proc/{entry.name}/stat", "rb") as f:
                    stat = f.read()
            except OSError:
                continue
            ppid = int(stat[stat.rindex(b")") + 2 :].split()[1])
            if ppid in wanted:
                found.add(int(entry.name))
    return found


def descendants(root: int) -> set[int]:
    """Every process below `root` (children, their children, ...)."""
    out: set[int] = set()
    level = {root}
    while level:
        level = children_of(level) - out
        out |= level
    return out


def end_tree(root: int, orphans: Callable[[], set[int]]) -> None:
    """SIGKILL `root`'s descendants and the `orphans()` that re-parented to this process,
    until none is left (a fork in between is caught on the next pass), and reap them."""
    for _ in range(50):
        targets = descendants(root) | orphans()
        if not targets:
            return
        for pid in targets:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, signal.SIGKILL)
        for pid in targets:  # our own children (orphans) are reaped here, others by theirs
            with contextlib.suppress(ChildProcessError, OSError):
                os.waitpid(pid, 0)
        time.sleep(0.01)
