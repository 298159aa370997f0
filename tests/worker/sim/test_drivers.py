"""The wanderer keeps off the walls; the waypoint follower visits its waypoints; path files."""

from __future__ import annotations

import numpy as np
import pytest

from worker.errors import InputError
from worker.sim.drivers import Wanderer, WaypointFollower, read_waypoints
from worker.sim.params import SimParams
from worker.sim.simulator import Simulator
from worker.world import World

RES = 0.05


def l_shaped_world() -> World:
    """An L-shaped flat: a 10 x 6 m room and a 2 m wide, 6 m long corridor off its side."""
    occ = np.ones((260, 260), dtype=bool)
    occ[1:121, 1:201] = False  # room: x in [0.05, 10.05), y in [0.05, 6.05)
    occ[120:241, 80:120] = False  # corridor up from the room: x in [4, 6), y up to 12
    occ[60, 100:140] = True  # a thin free-standing wall in the room
    return World.from_array(occ, RES, start_pose=(2.0, 3.0, 0.0), name="L")


def test_wanderer_roams_without_collisions():
    world = l_shaped_world()
    rng = np.random.default_rng(5)
    sim = Simulator(world, SimParams(), rng)
    wanderer = Wanderer(sim.params.laser, rng)
    visited = set()
    for _ in range(3000):  # 300 s
        v, w = wanderer.command(sim.scan(), sim.params.dt)
        sim.step(v, w)
        visited.add(world.world_to_cell(*sim.pose_gt[:2]))
    assert not sim.collisions
    # It covers ground: at least 150 distinct cells (7.5 m of straight travel at minimum).
    assert len(visited) > 150
    assert world.clearance[tuple(np.array(list(visited)).T[::-1])].min() > 0.2


def test_waypoint_follower_visits_every_waypoint():
    world = l_shaped_world()
    points = np.array([[8.0, 1.5], [8.0, 4.5], [5.0, 4.0], [5.0, 11.0]])
    sim = Simulator(world, SimParams(), np.random.default_rng(0))
    follower = WaypointFollower(points)
    reached = []
    for _ in range(1500):
        v, w = follower.command(sim.pose_gt)
        if len(reached) < follower.index:
            reached.append(sim.pose_gt[:2].copy())
        if follower.finished:
            break
        sim.step(v, w)
    assert follower.finished and not sim.collisions
    for target, got in zip(points, reached, strict=True):
        assert np.hypot(*(target - got)) <= follower.p.tolerance + 1e-9
    assert follower.command(sim.pose_gt) == (0.0, 0.0)


def test_read_waypoints(tmp_path):
    path = tmp_path / "p.txt"
    path.write_text("# a path\n1.0 2.0\n\n3,4  # comma separated\n-1e-1 5\n")
    np.testing.assert_allclose(read_waypoints(path), [[1, 2], [3, 4], [-0.1, 5]])
    path.write_text("1 2\n3 x\n")
    with pytest.raises(InputError, match="two numbers") as info:
        read_waypoints(path)
    assert info.value.line == 2
    path.write_text("1 2 3\n")
    with pytest.raises(InputError, match="expected `x y`"):
        read_waypoints(path)
    path.write_text("# nothing\n")
    with pytest.raises(InputError, match="no waypoints"):
        read_waypoints(path)
    with pytest.raises(InputError, match="no such file"):
        read_waypoints(tmp_path / "missing.txt")
