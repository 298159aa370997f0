"""How fast the results explorer answers over many stored runs: a scratch PostgreSQL database
holding N done runs (4 worlds x 3 algorithms x 3 settings, seeds, the outcomes mixed, scores
and parameters as the worker stores them), then GET /explore, /explore/groups.csv,
/explore/runs.csv and the scores plot, each timed over repeats (median and max wall time).

    python benchmarks/bench_explorer_page.py --runs 2000 --repeats 7
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from sqlalchemy import update  # noqa: E402

from backend.core.config import Settings  # noqa: E402
from backend.db.migrate import upgrade  # noqa: E402
from backend.db.models import Run  # noqa: E402
from backend.db.session import session_scope  # noqa: E402
from backend.store import add_user, save_world  # noqa: E402
from backend.store.jobs import create_job  # noqa: E402
from tests.services import ensure_redis, scratch_database  # noqa: E402
from tests.summaries import make_summary, relation  # noqa: E402
from tests.summaries import stats as rel_stats  # noqa: E402
from worker.run_params import RunParams  # noqa: E402
from worker.world.world import World  # noqa: E402

ALGORITHMS = ("rbpf", "graph", "odometry")
LIMITS = (None, 400.0, 900.0)  # the explore.time_limit of each setting (None: the default)


def _room():
    import numpy as np

    occ = np.zeros((80, 120), bool)
    occ[0, :] = occ[-1, :] = occ[:, 0] = occ[:, -1] = True
    return occ


def fill(url: str, n_runs: int) -> str:
    """Store `n_runs` done runs; returns the owner's API key."""
    import numpy as np

    rng = np.random.default_rng(1)
    with session_scope(url) as s:
        user, key = add_user(s, "bench")
        worlds = [save_world(s, owner_id=user.id, world=World.from_array(_room(), 0.05,
                  name=f"world_{i}"), sha256=f"w{i}", source_format="image").id
                  for i in range(4)]  # fmt: skip
        cells = [(w, a, lim) for w in worlds for a in ALGORITHMS for lim in LIMITS]
        per_cell = -(-n_runs // len(cells))
        made = 0
        for w, alg, lim in cells:
            params = RunParams(algorithm=alg).to_json()  # type: ignore[arg-type]
            if lim is not None:
                params["explore"]["time_limit"] = lim
            seeds = list(range(1, min(per_cell, n_runs - made) + 1))
            if not seeds:
                break
            job = create_job(s, owner_id=user.id, world_id=w, slam=alg, params=params,
                             seeds=seeds)  # fmt: skip
            made += len(seeds)
            for run in job.runs:
                kind = rng.choice(["completed", "time_limit", "collision"], p=[0.7, 0.2, 0.1])
                err = float(rng.uniform(0.02, 0.3))
                rels = {k: relation(rel_stats(err * f, 0.02, 300), rel_stats(0.01, 0.005, 300))
                        for k, f in (("B", 1.0), ("A", 1.3), ("SM", 0.8))}  # fmt: skip
                done = kind == "completed"
                summary = make_summary(
                    outcome="completed" if done else "failed",
                    reason=None if done else str(kind), stop="no_frontier" if done else str(kind),
                    relations={} if kind == "collision" else rels,
                )  # fmt: skip
                doc = summary.to_dict()
                b = rels["B"] if kind != "collision" else None
                s.execute(update(Run).where(Run.id == run.id).values(
                    status="done", outcome=doc["outcome"], reason=doc["reason"],
                    coverage=float(rng.uniform(0.5, 1.0)), summary=doc,
                    metrics={"relations": doc["relations"], "ate": doc["ate"]},
                    b_mean_t=b["translation"]["mean"] if b else None,
                    b_mean_r=b["rotation"]["mean"] if b else None,
                ))  # fmt: skip
    return key


def timed(client, path: str, repeats: int) -> tuple[float, float, int]:
    times = []
    size = 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = client.get(path)
        times.append(time.perf_counter() - t0)
        assert r.status_code == 200, (path, r.status_code, r.text[:300])
        size = len(r.content)
    return statistics.median(times), max(times), size


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    from fastapi.testclient import TestClient

    from mapqual.app import create_app

    with scratch_database("mapqual_bench") as url:
        upgrade(url)
        t0 = time.perf_counter()
        key = fill(url, args.runs)
        print(f"stored {args.runs} runs in {time.perf_counter() - t0:.1f} s")
        redis_url = ensure_redis().rsplit("/", 1)[0] + "/13"
        client = TestClient(create_app(Settings(DATABASE_URL=url, REDIS_URL=redis_url)),
                            base_url="https://testserver")  # fmt: skip
        client.headers["Authorization"] = f"Bearer {key}"
        client.get("/explore")  # warm: imports, template compilation, connection pool
        print(f"{'request':58s} {'median [s]':>10s} {'max [s]':>8s} {'bytes':>9s}")
        for path in ("/explore", "/explore?applied=1&kind=completed&by=slam",
                     "/explore?applied=1&kind=completed&kind=time+limit&by=world&by=slam"
                     "&by=setting&world=world_1", "/explore/groups.csv", "/explore/runs.csv",
                     "/explore/plot/scores.png?world=world_1",
                     "/explore/plot/scores.png?world=world_1&dpi=220", "/compare"):  # fmt: skip
            med, worst, size = timed(client, path, args.repeats)
            print(f"{path[:58]:58s} {med:10.3f} {worst:8.3f} {size:9d}")


if __name__ == "__main__":
    main()
