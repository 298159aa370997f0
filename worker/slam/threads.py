"""How many scan-matching threads a run gets: the cores its process was given when it runs
alone (`mapqual run`, a worker with --concurrency 1), one each when runs share the machine
(a batch's pool, a worker with several processes). Results do not depend on it
(`SlamParams.threads`); only the wall time does.

The process's share is MAPQUAL_SLAM_THREADS (set by `mapqual run` and `mapqual worker` when
unset, inherited by a worker's processes); a run whose params ask for more than one thread
keeps its own number.
"""

from __future__ import annotations

import os
from dataclasses import replace

from worker.errors import InputError

ENV = "MAPQUAL_SLAM_THREADS"


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def process_threads() -> int:
    """This process's scan-matching threads: MAPQUAL_SLAM_THREADS, else 1."""
    raw = os.environ.get(ENV, "").strip()
    if not raw:
        return 1
    try:
        n = int(raw)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"{ENV} must be a whole number >= 1, got {raw!r}")
    return n


def share_for(processes: int) -> int:
    """Threads for each of `processes` runs in parallel on this process's cores (>= 1)."""
    return max(1, cores() // max(1, processes))


def claim_default(processes: int = 1) -> None:
    """Set MAPQUAL_SLAM_THREADS to the share of `processes` parallel runs, unless it is set
    already (the caller's choice wins)."""
    if not os.environ.get(ENV, "").strip():
        os.environ[ENV] = str(share_for(processes))


def with_process_threads(params):
    """`params` (RunParams) with slam.threads = this process's share when the run left it at
    the default 1."""
    n = process_threads()
    if params.slam.threads != 1 or n == 1:
        return params
    return replace(params, slam=replace(params.slam, threads=n))
