"""Closed-loop exploration on purpose-built worlds and a Bormann floorplan (real simulator)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from worker.explore.flat_params import explore_params
from worker.explore.loop import explore
from worker.sim.params import SimParams
from worker.sim.simulator import Simulator
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam
from worker.world.loader import load_world
from worker.world.world import World

RES = 0.05
WORLDS = Path(__file__).resolve().parents[3] / "worlds" / "bormann"


def _box(h_m: float, w_m: float) -> np.ndarray:
    """Occupancy grid `(H, W)` of a closed box: 0.1 m thick outer walls."""
    occ = np.zeros((round(h_m / RES), round(w_m / RES)), dtype=bool)
    occ[:2, :] = occ[-2:, :] = occ[:, :2] = occ[:, -2:] = True
    return occ


def _cells(m: float) -> int:
    return round(m / RES)


def _run(world: World, seed: int = 3, **params):
    rng = np.random.default_rng(seed)
    sim_params = SimParams()
    sim = Simulator(world, sim_params, rng)
    slam = make_slam("odometry", sim_params.laser, SlamParams(), rng)
    progress = []
    result = explore(
        world, sim, slam, explore_params(**params), oracle=True, on_progress=progress.append
    )
    return result, progress


def _assert_clean_completion(result, min_coverage=0.95):
    assert result.outcome == "completed", (result.reason, result.stop_detail)
    assert result.reason == "no_frontier"
    assert result.collision is None
    assert result.coverage >= min_coverage, result.coverage


def _dead_end_world() -> World:
    """A 5 x 5 m room with a 1.2 m wide, 7.8 m long dead-end corridor leaving it to the right,
    seen from the start at an angle (the corridor's end is hidden)."""
    occ = _box(5.0, 13.0)
    occ[:, _cells(5.0) : _cells(5.1)] = True  # the room's right wall
    occ[_cells(3.4) : _cells(4.6), _cells(5.0) : _cells(5.1)] = False  # the corridor's mouth
    occ[: _cells(3.4), _cells(5.1) :] = True  # solid below the corridor
    occ[_cells(4.6) :, _cells(5.1) :] = True  # and above it
    return World.from_array(occ, RES, start_pose=(1.0, 1.0, 0.0), name="dead_end")


def test_dead_end_corridor_is_explored_to_its_end_and_left_again():
    world = _dead_end_world()
    result, progress = _run(world, time_limit=600.0)
    _assert_clean_completion(result)
    # the robot went into the corridor (its end is out of sight from the room) and came back
    # out of it, or finished there with nothing left to see
    assert result.pose_gt[:, 0].max() > 5.5
    # same 10 Hz timestamps for both paths, starting at 0
    assert np.allclose(np.diff(result.t), 0.1) and result.t[0] == 0.0
    assert result.pose_gt.shape == result.pose_est.shape == (len(result.t), 3)
    np.testing.assert_allclose(result.pose_est, result.pose_gt, atol=1e-9)  # oracle
    assert progress and progress[-1].t <= result.t[-1]
    assert all(0.0 <= p.coverage <= 1.0 for p in progress)


@pytest.mark.parametrize("door_m", [0.6, 0.7, 0.9])
def test_room_behind_a_narrow_door_is_explored(door_m):
    # two 4 x 4 m rooms joined by one door in the wall between them; 0.6 m = the 0.4 m robot
    # plus 0.1 m each side, exactly what the planner's margin leaves passable
    occ = _box(4.0, 8.1)
    occ[:, _cells(4.0) : _cells(4.1)] = True
    lo = _cells(2.0 - door_m / 2)
    occ[lo : lo + _cells(door_m), _cells(4.0) : _cells(4.1)] = False
    # a partition in the second room hides its lower right part from the door
    occ[: _cells(2.8), _cells(5.5) : _cells(5.6)] = True
    world = World.from_array(occ, RES, start_pose=(1.0, 1.0, 0.0), name="narrow_door")
    result, _ = _run(world, time_limit=600.0)
    _assert_clean_completion(result)
    assert result.pose_gt[:, 0].max() > 5.6  # went through the door and past the partition


def test_unreachable_regions_do_not_keep_the_robot_busy():
    # left: the robot's 5 x 5 m room; right, behind a 0.25 m slit (narrower than the robot):
    # a 3 x 5 m room it can glimpse but not enter; top right: a closed cell it never sees
    occ = _box(5.0, 9.0)
    occ[:, _cells(5.0) : _cells(5.1)] = True
    occ[_cells(2.4) : _cells(2.65), _cells(5.0) : _cells(5.1)] = False  # the slit
    occ[_cells(3.5) : _cells(3.6), _cells(5.1) :] = True  # the closed cell's floor
    world = World.from_array(occ, RES, start_pose=(1.5, 1.5, 0.0), name="unreachable")
    result, _ = _run(world, time_limit=900.0)
    _assert_clean_completion(result)
    assert result.pose_gt[:, 0].max() < 5.0  # never got through the slit
    assert result.t[-1] < 600.0  # and did not spend long trying


def test_diverging_slam_pose_fails_the_run_as_slam_diverged():
    world = _dead_end_world()

    class DriftingSlam:
        """The real odometry mapper, but its pose estimate slides away at 1 m/s."""

        def __init__(self, inner):
            self.inner = inner
            self.t = 0.0

        def process(self, t, pose, ranges):
            self.t = t
            return self.inner.process(t, pose, ranges)

        def pose_estimate(self):
            return self.inner.pose_estimate() + np.array([self.t, 0.0, 0.0])

        def T_map_odom(self):
            return self.inner.T_map_odom()

        def occupancy(self):
            return self.inner.occupancy()

    rng = np.random.default_rng(0)
    sim = Simulator(world, SimParams(), rng)
    slam = DriftingSlam(make_slam("odometry", SimParams().laser, SlamParams(), rng))
    result = explore(world, sim, slam, explore_params(time_limit=60.0), oracle=True)
    assert result.outcome == "failed" and result.reason == "slam_diverged"
    # 3 m at 1 m/s: the step at 3 s (exactly 3 m: rounding decides) or the next
    assert 2.95 < result.t[-1] <= 3.15


def test_bormann_oracle_exploration_completes():
    # the CI's representative whole building; benchmarks/bench_explore.py --proof runs the rest
    world = load_world(WORLDS / "Freiburg52_scan.yaml")
    result, _ = _run(world, seed=1, time_limit=1800.0)
    _assert_clean_completion(result)
    assert result.goals_reached > 5
    assert result.path_length_m > 40.0  # it toured the building: rooms on both sides


def test_the_navigation_grids_are_let_go_before_the_final_map_is_assembled():
    """The run's end assembles and judges the final map: the costmap's and the planners'
    map-sized grids are gone by then (nothing refers to them), and what the result reports of
    the navigation (goals, safety triggers, recoveries) was read before."""
    import weakref

    from worker.explore.loop import Exploration

    world = _dead_end_world()
    rng = np.random.default_rng(3)
    sim = Simulator(world, SimParams(), rng)
    slam = make_slam("odometry", SimParams().laser, SlamParams(), rng)
    run = Exploration(world, sim, slam, explore_params(time_limit=60.0), True, None)
    stop = None
    while stop is None:
        stop = run.step()
    nav = run.nav
    navigator = weakref.ref(nav)  # its grids go with it
    goals, triggers = tuple(nav.stats.goals), nav.safety.n_triggers
    assert goals and nav.costmap.inflated.size > 10_000
    seen_at_assembly = []
    name = "occupancy_with_hits" if hasattr(slam, "occupancy_with_hits") else "occupancy"
    occupancy = getattr(slam, name)

    def assembly():
        seen_at_assembly.append(navigator() is None)
        return occupancy()

    setattr(slam, name, assembly)
    del nav
    result = run.result(stop)
    assert seen_at_assembly == [True]
    assert result.goals == goals and result.safety_triggers == triggers


def test_the_heap_is_given_back_after_each_whole_map_read_and_at_the_end(monkeypatch):
    """glibc keeps freed memory in its heap: the run gives it back after each whole-map read
    (every full_map_check_period; 4 s here) and at its end, not at every step."""
    import worker.explore.loop as loop_module

    calls = []
    monkeypatch.setattr(loop_module, "release_free_heap", lambda: calls.append(1) or True)
    result, _ = _run(_dead_end_world(), time_limit=95.0, full_map_check_period=4.0)
    assert result.t[-1] > 12.0
    # the whole-map reads come with the map updates at 2 Hz, the first one 4 s on or later
    reads = int(result.t[-1] // 4.0)
    assert reads - 1 <= len(calls) - 1 <= reads, (len(calls), result.t[-1])
    assert len(calls) < len(result.t) / 10
