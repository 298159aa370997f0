"""Peak resident memory in each phase of one run (load_world, the exploration, the relations'
evaluation, the map score, the summary), sampled every 2 ms: where a large plan's peak is set.

    python benchmarks/probe_phases.py PLAN.yaml [--time-limit S] [--slam rbpf] [--seed 1]
        [--parts 60] [--stacks]

--parts P also prints, every P seconds simulated, the coverage, the resident size and each
component's resident bytes (memory_parts.py: the pages of its arrays the kernel has mapped) and
array bytes: what grows along the run, and what of the resident size no component holds.
--stacks prints, after each phase, the main thread's Python stack (its 8 innermost frames) at
the moment the phase's peak was reached, sampled every millisecond: which step sets the peak.
--report runs as `mapqual run` does: with a progress callback (so with the live coverage and
the timeline) and then writes the report folder (worker.report.folder.write_report, a phase
of its own) into a temporary folder.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import worker.pipeline as pl
from worker.run_params import RunParams
from worker.world.loader import load_world

sys.path.insert(0, str(Path(__file__).resolve().parent))
from memory_parts import _exploration, peak_mb, sample  # noqa: E402


class Sampler:
    """The process's resident size [MiB], its highest value since `reset`; with `stacks`, the
    main thread's Python stack where that highest value was reached."""

    def __init__(self, stacks: bool = False) -> None:
        self.top = 0.0
        self.main = threading.get_ident()
        self.stacks = stacks
        self.where: list[str] = []  # the stack at `top`, innermost last
        threading.Thread(target=self._loop, daemon=True).start()

    @staticmethod
    def now() -> float:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096 / 2**20

    def reset(self) -> float:
        self.top, self.where = self.now(), []
        return self.top

    def _loop(self) -> None:
        while True:
            now = self.now()
            if now > self.top:
                self.top = now
                frame = sys._current_frames().get(self.main) if self.stacks else None
                if frame is not None:
                    # a frame numba's compiler swapped under us: this peak's stack is lost,
                    # the sampling goes on
                    with contextlib.suppress(AttributeError, ValueError):
                        self.where = [f"{Path(f.filename).name}:{f.lineno} {f.name}"
                                      for f in traceback.extract_stack(frame)[-8:]]  # fmt: skip
            time.sleep(0.001 if self.stacks else 0.002)


def _timed(rss: Sampler, name: str, f: Callable) -> Callable:
    def phase(*args, **kwargs):
        before = rss.reset()
        out = f(*args, **kwargs)
        print(f"{name:12s} before {before:6.0f}  peak {rss.top:6.0f}  after {rss.now():6.0f} MiB")
        if rss.where:
            print("    peak reached in: " + " > ".join(rss.where))
        return out

    return phase


class _Mallinfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks",
        "fordblks", "keepcost")]  # fmt: skip


def heap_mb() -> str:
    """glibc's own view (mallinfo2): bytes in use from its heaps and mmaps, and bytes free in
    its heaps that it has not given back to the system."""
    try:
        f = ctypes.CDLL(None).mallinfo2
    except (AttributeError, OSError):
        return "heap ?"
    f.restype = _Mallinfo2
    m = f()
    used, kept = (m.uordblks + m.hblkhd) / 2**20, m.fordblks / 2**20
    return f"malloc in use {used:.0f} MiB, free kept {kept:.0f} MiB"


def parts_printer(period: float, rss: Sampler) -> Callable:
    """An on_progress callback printing the components every `period` simulated seconds."""
    next_t = [0.0]

    def on_progress(progress) -> None:
        t = float(getattr(progress, "t", 0.0))
        run = _exploration()
        if run is None or t < next_t[0]:
            return
        next_t[0] = t + period
        res, arr = sample(run, resident=True), sample(run)
        cells = " ".join(f"{k} {res[k] / 2**20:.0f}/{arr[k] / 2**20:.0f}" for k in res)
        cov = float(getattr(progress, "coverage", 0.0))
        print(f"t {t:6.0f} s  coverage {cov:.3f}  resident {rss.now():6.0f} MiB  "
              f"(resident/array MiB) {cells}; {heap_mb()}", flush=True)  # fmt: skip

    return on_progress


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan", type=Path, help="a map_server YAML")
    ap.add_argument("--time-limit", type=float, default=120.0, help="[s] simulated")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--parts", type=float, default=None, help="[s] simulated between prints")
    ap.add_argument("--stacks", action="store_true", help="where each phase's peak was reached")
    ap.add_argument("--report", action="store_true", help="as `mapqual run`: progress, report")
    args = ap.parse_args()
    rss = Sampler(args.stacks)
    for name in ("explore", "_evaluate", "_map_score", "_summary"):
        setattr(pl, name, _timed(rss, name.strip("_"), getattr(pl, name)))
    world = _timed(rss, "load_world", load_world)(args.plan)
    params = RunParams.from_json(
        {"algorithm": args.slam, "explore": {"time_limit": args.time_limit}}
    )
    on_progress = None if args.parts is None else parts_printer(args.parts, rss)
    if args.report and on_progress is None:
        on_progress = _ignore
    result = pl.run_one(world, params, args.seed, on_progress)
    if args.report:
        from worker.report.folder import write_report

        with tempfile.TemporaryDirectory() as folder:
            _timed(rss, "report", write_report)(result, Path(folder))
    print(f"whole process: peak {peak_mb():.0f} MiB (VmHWM)")


def _ignore(progress) -> None:
    """A progress callback that does nothing: the run measures what `mapqual run`'s does."""


if __name__ == "__main__":
    main()
