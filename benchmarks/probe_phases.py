"""Peak resident memory in each phase of one run (load_world, the exploration, the relations'
evaluation, the map score, the summary), sampled every 2 ms: where a large plan's peak is set.

    python benchmarks/probe_phases.py PLAN.yaml [--time-limit S] [--slam rbpf] [--seed 1]
"""

from __future__ import annotations

import argparse
import threading
import time
from collections.abc import Callable
from pathlib import Path

import worker.pipeline as pl
from worker.run_params import RunParams
from worker.world.loader import load_world


class Sampler:
    """The process's resident size [MiB], its highest value since `reset`."""

    def __init__(self) -> None:
        self.top = 0.0
        threading.Thread(target=self._loop, daemon=True).start()

    @staticmethod
    def now() -> float:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * 4096 / 2**20

    def reset(self) -> float:
        self.top = self.now()
        return self.top

    def _loop(self) -> None:
        while True:
            self.top = max(self.top, self.now())
            time.sleep(0.002)


def _timed(rss: Sampler, name: str, f: Callable) -> Callable:
    def phase(*args, **kwargs):
        before = rss.reset()
        out = f(*args, **kwargs)
        print(f"{name:12s} before {before:6.0f}  peak {rss.top:6.0f}  after {rss.now():6.0f} MiB")
        return out

    return phase


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan", type=Path, help="a map_server YAML")
    ap.add_argument("--time-limit", type=float, default=120.0, help="[s] simulated")
    ap.add_argument("--slam", default="rbpf")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    rss = Sampler()
    for name in ("explore", "_evaluate", "_map_score", "_summary"):
        setattr(pl, name, _timed(rss, name.strip("_"), getattr(pl, name)))
    world = _timed(rss, "load_world", load_world)(args.plan)
    params = RunParams.from_json(
        {"algorithm": args.slam, "explore": {"time_limit": args.time_limit}}
    )
    pl.run_one(world, params, args.seed)


if __name__ == "__main__":
    main()
