"""Memory and time of the reachable free cells (worker.evaluate.coverage.reachable_free, called
twice at a run's start and once in its evaluation) against scipy's whole-plan transforms that
it replaced (tests/worker/evaluate/test_reachable.py's reference), on one plan, each in a
fresh process: peak resident memory above what the process held before the call (sampled
every millisecond; the bounded way's includes loading its numba kernels from the cache).

    python benchmarks/bench_reachable.py PLAN.yaml [--rounds 2]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHILD = """
import gc, json, sys, threading, time
import numpy as np
occ = np.load(sys.argv[2])
from tests.worker.evaluate.test_reachable import scipy_reachable
from worker.evaluate.coverage import reachable_free
iy = occ.shape[0] // 2
row = np.flatnonzero(~occ[iy])
ix = int(row[len(row) // 2])
f = reachable_free if sys.argv[1] == "bounded" else scipy_reachable
gc.collect()
rss = lambda: int(open("/proc/self/statm").read().split()[1]) * 4096
before, top, done = rss(), [0], []
def sample():  # the resident size every millisecond: ru_maxrss cannot see under an earlier peak
    while not done:
        top[0] = max(top[0], rss())
        time.sleep(0.001)
watcher = threading.Thread(target=sample)
watcher.start()
t0 = time.perf_counter()
cells = int(f(occ, float(sys.argv[3]), (ix, iy), 0.2).sum())
wall = time.perf_counter() - t0
done.append(1)
watcher.join()
print(json.dumps({"way": sys.argv[1], "cells_reachable": cells, "wall_s": round(wall, 3),
                  "peak_rise_mib": round((top[0] - before) / 2**20, 1)}))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("plan", type=Path, help="a map_server YAML")
    ap.add_argument("--rounds", type=int, default=2)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from worker.world.loader import load_world

    world = load_world(args.plan)
    occ_file = Path("/tmp") / f"bench_reachable_{world.name}.npy"
    import numpy as np

    np.save(occ_file, world.occ)
    print(f"{world.name}: {world.occ.size / 1e6:.1f} M cells at {world.resolution} m")
    room = "occ = np.ones((50, 50), bool); occ[1:-1, 1:-1] = False"  # a room, to compile in
    warm = CHILD.replace("occ = np.load(sys.argv[2])", room)
    subprocess.run([sys.executable, "-c", warm, "bounded", str(occ_file), "0.05"], cwd=ROOT,
                   check=True, capture_output=True)  # fmt: skip  # numba's cache written
    for _ in range(args.rounds):
        for way in ("scipy", "bounded"):
            out = subprocess.run(
                [sys.executable, "-c", CHILD, way, str(occ_file), str(world.resolution)],
                cwd=ROOT, capture_output=True, text=True, check=True,
            )  # fmt: skip
            print(out.stdout.strip())
    occ_file.unlink()


if __name__ == "__main__":
    main()
