"""A real finished run with its report folder and sim.log, and the same run stored in a database."""

from __future__ import annotations

from pathlib import Path

from backend.db.session import session_scope
from backend.store import create_job, save_world
from tests.backend.finished_runs import store_finished_run
from tests.worker.test_pipeline import two_rooms
from worker.pipeline import RunResult, run_one
from worker.report.folder import write_report
from worker.run_params import RunParams

PARAMS = {
    "algorithm": "odometry",
    "sim": {"odom_model": "gaussian", "odom_sigmas": [0.05, 0.05, 0.05]},
    "explore": {"time_limit": 60.0},
    "eval": {"b": {"min_relations": 300}},
}


def finished_run(folder: Path) -> RunResult:
    """Odometry SLAM with Gaussian odometry noise in two_rooms (B: at least 300 relations),
    its report and sim.log written to `folder`."""
    result = run_one(two_rooms(), RunParams.from_json(PARAMS), seed=4, sim_log=folder / "sim.log")
    write_report(result, folder)
    return result


def store_run(url: str, owner_id: int, result: RunResult, folder: Path) -> int:
    """The run stored as a finished run of `owner_id` (a world and a job of its own): its id."""
    with session_scope(url) as s:
        w = save_world(s, owner_id=owner_id, world=result.world, sha256=f"rooms-{owner_id}",
                       source_format="image")  # fmt: skip
        job = create_job(s, owner_id=owner_id, world_id=w.id, slam="odometry",
                         params=result.params.to_json(), seeds=[result.seed])  # fmt: skip
        run_id = job.runs[0].id
    store_finished_run(url, run_id, result, folder)
    return run_id
