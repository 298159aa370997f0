"""A batch's plan of jobs: runs that differ by their seed only share a job; any other
difference (world, parameters) makes another; jobs keep the order of their first run."""

from __future__ import annotations

from worker.batch.experiment import RunSpec
from worker.batch.jobs import cell_key, plan_cells, source_format


def _spec(seed: int, world: str = "a", noise: float = 0.0) -> RunSpec:
    params = {"algorithm": "odometry", "sim": {"laser_noise_sigma": noise}}
    return RunSpec(
        key=f"{world}-{noise}-{seed}", world_path=f"/w/{world}.yaml", world=world, base=world,
        variant="no_furniture", slam="odometry", noise=noise, seed=seed, params=params,
    )  # fmt: skip


def test_runs_differing_by_seed_only_make_one_job_and_others_their_own():
    specs = [_spec(1), _spec(1, noise=0.1), _spec(2), _spec(1, world="b"), _spec(2, noise=0.1)]
    cells = plan_cells(specs)
    assert [[s.key for s in c.specs] for c in cells] == [
        ["a-0.0-1", "a-0.0-2"], ["a-0.1-1", "a-0.1-2"], ["b-0.0-1"],
    ]  # fmt: skip
    first = cells[0]
    assert (first.world_path, first.slam, first.seeds) == ("/w/a.yaml", "odometry", [1, 2])
    assert first.params == {"algorithm": "odometry", "sim": {"laser_noise_sigma": 0.0}}
    assert first.idempotency_key("b1") == f"batch:b1:{cell_key(specs[0])}"


def test_a_jobs_key_ignores_the_seed_and_the_order_of_parameter_keys():
    a, b = _spec(1), _spec(9)
    reordered = RunSpec(
        **{**a.__dict__, "params": {"sim": a.params["sim"], "algorithm": "odometry"}}
    )
    assert cell_key(a) == cell_key(b) == cell_key(reordered)
    assert cell_key(a) != cell_key(_spec(1, noise=0.3))
    assert len(cell_key(a)) == 16


def test_a_stage_world_is_stored_as_stage_and_anything_else_as_yaml():
    assert source_format("/w/office.world") == "stage"
    assert source_format("/w/office.yaml") == "yaml"
