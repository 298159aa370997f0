"""Peak memory of a run per component, for bench_run.py and run_once.py (issue 52).

Measured as the bytes of the numpy arrays each component holds (`nbytes`, each buffer counted
once), sampled at every progress report of the run (each simulated second) and kept at its
maximum: what the component's state weighs at its largest, not the allocator's view, and
blind to scratch arrays freed within a step (a numba kernel's temporaries, a pool's growth
copy). The report stage is measured apart, with tracemalloc (numpy reports its allocations
to it), as its peak of traced allocations while the report files are written.

The components are found from the progress callback's caller, the exploration loop
(worker.explore.loop.Exploration): its slam (particle maps), nav.costmap and nav.local
(costmap), the rest of nav (planners: frontier search, global planner, DWA, trail, door,
safety), sim and world with the reachability masks (simulator) and the trajectory recording.
"""

from __future__ import annotations

import os
import resource
import sys
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

PARTS = ("particle maps", "costmap", "planners", "simulator", "recording")
_COSTMAP = ("costmap", "local")
_MAX_DEPTH = 8


def array_bytes(obj: Any, seen: set[int], depth: int = 0, resident: bool = False) -> int:
    """Bytes of the numpy arrays reachable from obj (attributes, slots, containers), each
    buffer counted once across calls sharing `seen` (a view counts as its base). resident:
    only the bytes of the pages the kernel has mapped (`resident_bytes`), not `nbytes`: a
    zeroed buffer whose pages were never written weighs nothing."""
    if depth > _MAX_DEPTH or isinstance(obj, str | bytes | int | float | bool | type(None)):
        return 0
    if isinstance(obj, np.ndarray):
        base = obj
        while isinstance(base.base, np.ndarray):
            base = base.base
        if id(base) in seen:
            return 0
        seen.add(id(base))
        return resident_bytes(base) if resident else int(base.nbytes)
    if id(obj) in seen or callable(obj) and not hasattr(obj, "__dict__"):
        return 0
    seen.add(id(obj))
    if isinstance(obj, dict):
        children = list(obj.values())
    elif isinstance(obj, list | tuple | set | frozenset):
        children = list(obj)
    else:
        children = list(getattr(obj, "__dict__", {}).values())
        for cls in type(obj).__mro__:
            for name in getattr(cls, "__slots__", ()):
                if hasattr(obj, name):
                    children.append(getattr(obj, name))
    return sum(array_bytes(c, seen, depth + 1, resident) for c in children)


def _exploration() -> Any:
    """The Exploration object whose progress report is being handled (up the call stack)."""
    frame = sys._getframe(2)
    while frame is not None:
        me = frame.f_locals.get("self")
        if type(me).__name__ == "Exploration" and hasattr(me, "nav"):
            return me
        frame = frame.f_back
    return None


def sample(run: Any, resident: bool = False) -> dict[str, int]:
    """Bytes per component of one exploration loop now (resident: see `array_bytes`)."""
    seen: set[int] = set()
    nav = run.nav
    out = {"particle maps": array_bytes(run.slam, seen, 0, resident)}
    out["costmap"] = sum(array_bytes(getattr(nav, n, None), seen, 0, resident) for n in _COSTMAP)
    rest = {k: v for k, v in vars(nav).items() if k not in _COSTMAP}
    out["planners"] = array_bytes(rest, seen, 0, resident)
    sim = (run.sim, run.world, getattr(run, "reach", None), getattr(run, "passable", None))
    out["simulator"] = array_bytes(sim, seen, 0, resident)
    out["recording"] = array_bytes(getattr(run, "rec", None), seen, 0, resident)
    return out


def resident_bytes(a: np.ndarray) -> int:
    """Bytes of the pages under `a`'s buffer that are resident (Linux /proc/self/pagemap: bit
    63 of each page's entry), at most `a.nbytes`; `a.nbytes` where the map cannot be read."""
    if a.nbytes == 0:
        return 0
    page = os.sysconf("SC_PAGE_SIZE")
    addr = a.__array_interface__["data"][0]
    first, last = addr // page, (addr + a.nbytes - 1) // page
    try:
        with open("/proc/self/pagemap", "rb") as f:
            f.seek(first * 8)
            entries = np.frombuffer(f.read((last - first + 1) * 8), dtype=np.uint64)
    except OSError:
        return int(a.nbytes)
    # a small array shares its pages with others: at most its own bytes
    return min(int(np.count_nonzero(entries >> np.uint64(63))) * page, int(a.nbytes))


def resident_mb() -> float:
    """The process's resident memory now [MiB] (Linux: /proc/self/statm), 0 elsewhere."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
    except (OSError, IndexError, ValueError):
        return 0.0
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def peak_mb() -> float:
    """The process's peak resident memory [MiB] since its start or since the peak was reset
    (/proc/self/clear_refs): VmHWM, getrusage's maximum where /proc is missing."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def peak_sampler(
    trace: list | None = None, trace_period: float = 60.0
) -> tuple[Callable[[Any], None], dict[str, int]]:
    """(on_progress callback, peaks): each call samples the components of the run that
    called it and keeps the maxima in peaks (bytes). trace: a list that gets, every
    trace_period of simulated time [s], [t, coverage, resident MiB, particle maps MiB,
    planners MiB]: how the memory grows along the run."""
    peaks = dict.fromkeys(PARTS, 0)
    next_t = [0.0]

    def on_progress(progress: Any) -> None:
        run = _exploration()
        if run is None:
            return
        now = sample(run)
        for k, v in now.items():
            peaks[k] = max(peaks[k], v)
        t = float(getattr(progress, "t", 0.0))
        if trace is not None and t >= next_t[0]:
            next_t[0] = t + trace_period
            mib = [round(now[k] / 2**20, 1) for k in ("particle maps", "planners")]
            cov = round(float(getattr(progress, "coverage", 0.0)), 3)
            trace.append([round(t), cov, round(resident_mb()), *mib])

    return on_progress, peaks


def traced_peak(fn: Callable[[], Any]) -> tuple[Any, int]:
    """(fn(), the peak bytes of allocations traced by tracemalloc while it ran)."""
    tracemalloc.start()
    try:
        out = fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    return out, int(peak)
