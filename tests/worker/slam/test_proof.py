"""Proof on simulated logs in Bormann worlds: rbpf halves odometry's B error and maps the walls.

Short wander logs (CI time) with the Stage odometry model and a harsher Gaussian one (5 % of
each step's translation and rotation, 0.05 rad per metre, against 2 % / 1 % by default); 20
particles instead of the thesis's 40 for the same reason (benchmarks/bench_slam.py runs the
thesis settings on a long log).
"""

from __future__ import annotations

import numpy as np
import pytest

from worker.evaluate.metric import evaluate_relations
from worker.evaluate.relations import BParams, relations_B
from worker.evaluate.trajectory import Trajectory
from worker.sim.carmen import read_laser_log
from worker.sim.params import SimParams
from worker.sim.run import run_simulation
from worker.slam.overlap import wall_overlap
from worker.slam.params import SlamParams
from worker.slam.run import run_slam
from worker.world import load_world

DURATION = 100.0  # [s] simulated
HARSH = (0.05, 0.05, 0.05)  # Gaussian odometry sigmas (used by the "gaussian" model only)
CASES = [
    ("office_a", "stage", 1),
    ("office_a", "gaussian", 2),
    ("office_d", "stage", 3),
    ("lab_ipa", "gaussian", 4),
]


@pytest.mark.slow
@pytest.mark.parametrize("world_name, odom_model, seed", CASES)
def test_rbpf_beats_odometry_and_maps_the_walls(tmp_path, world_name, odom_model, seed):
    world = load_world(f"worlds/bormann/{world_name}.yaml")
    sim_params = SimParams(odom_model=odom_model, odom_sigmas=HARSH)
    run_simulation(world, tmp_path, seed=seed, duration_s=DURATION, params=sim_params)
    log = read_laser_log(tmp_path / "sim.log")
    gt = Trajectory(log.t_gt, log.pose_gt)
    results = {
        name: run_slam(
            log.t,
            log.pose_odom,
            log.ranges,
            log.laser,
            name,
            SlamParams(particles=20),
            np.random.default_rng(seed),
        )
        for name in ("odometry", "rbpf")
    }
    # the same B relations for both: drawn with N sized on the odometry estimate
    rel = relations_B(
        gt,
        results["odometry"].trajectory,
        np.random.default_rng(seed),
        BParams(min_relations=500, max_relations=5000),
    )
    err = {k: evaluate_relations(rel, r.trajectory).summary() for k, r in results.items()}
    b_odom = err["odometry"]["translation"]["mean"]
    b_rbpf = err["rbpf"]["translation"]["mean"]
    assert err["rbpf"]["skipped"] == 0
    assert b_odom > 0.05  # the odometry drifts measurably on this log
    assert b_rbpf <= 0.5 * b_odom, (b_rbpf, b_odom)
    ov = {
        k: wall_overlap(r.grid, world.occ, world.resolution, world.origin, tol=0.1)
        for k, r in results.items()
    }
    print(
        f"{world_name} {odom_model}: B mean odometry {b_odom:.3f} m, rbpf {b_rbpf:.3f} m; walls "
        f"rbpf precision {ov['rbpf'].precision:.3f} recall {ov['rbpf'].recall:.3f}, odometry "
        f"precision {ov['odometry'].precision:.3f} recall {ov['odometry'].recall:.3f}"
    )  # shown with pytest -s
    assert ov["rbpf"].precision >= 0.95 and ov["rbpf"].recall >= 0.85, ov["rbpf"]
    assert ov["rbpf"].precision > ov["odometry"].precision
