"""The odometry baseline and the interface: maps a closed-form room, gating, input errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.slam.base import SlamAlgorithm
from worker.slam.gating import UpdateGate
from worker.slam.params import SlamParams
from worker.slam.registry import make_slam

from .helpers import Laser, box_scan

BOX = (0.0, 0.0, 8.0, 5.0)


def _cell_centres(grid, mask):
    iy, ix = np.nonzero(mask)
    return np.stack([grid.origin[0] + (ix + 0.5) * grid.resolution,
                     grid.origin[1] + (iy + 0.5) * grid.resolution], axis=1)  # fmt: skip


def _distance_to_box_walls(xy):
    x0, y0, x1, y1 = BOX
    return np.minimum.reduce([abs(xy[:, 0] - x0), abs(xy[:, 0] - x1),
                              abs(xy[:, 1] - y0), abs(xy[:, 1] - y1)])  # fmt: skip


def test_odometry_maps_the_room_at_the_given_poses():
    laser = Laser()
    slam = make_slam("odometry", laser, None, np.random.default_rng(1))
    assert isinstance(slam, SlamAlgorithm) and slam.name == "odometry"
    poses = [np.array([2.0, 2.5, 0.3]), np.array([4.0, 2.0, 2.0]), np.array([6.0, 3.0, -2.5])]
    for k, pose in enumerate(poses):
        assert slam.process(k * 10.0, pose, box_scan(pose, laser.angles, BOX))
    assert np.allclose(slam.pose_estimate(), poses[-1]) and np.allclose(slam.T_map_odom(), 0)
    g = slam.occupancy()
    occ = _cell_centres(g, g.occupied)
    # every occupied cell is on a wall (within one cell of the line), and the walls are mapped
    assert _distance_to_box_walls(occ).max() <= 1.5 * g.resolution
    assert len(occ) > 2 * (8 + 5) / 0.05 * 0.8
    free = _cell_centres(g, g.free)
    # free cells lie inside the room, give or take the cell a beam ends in (Bresenham may step
    # into the wall's row one cell early)
    x0, y0, x1, y1 = np.array(BOX) + np.array([-1, -1, 1, 1]) * g.resolution
    inside = (free[:, 0] > x0) & (free[:, 0] < x1) & (free[:, 1] > y0) & (free[:, 1] < y1)
    assert inside.all()
    # the room's inside is almost all seen free
    assert len(free) > 0.9 * (8 * 5) / 0.05**2 * 0.9
    # the map covers the room, not more: grown to the explored area
    assert g.shape[0] * g.resolution < 5.2 and g.shape[1] * g.resolution < 8.2


def test_gate_linear_angular_temporal():
    gate = UpdateGate(1.0, 0.25, -1.0)
    assert gate.step(0.0, np.array([0.0, 0.0, 0.0]))  # first scan always
    assert not gate.step(0.1, np.array([0.6, 0.0, 0.0]))
    assert gate.step(0.2, np.array([1.0, 0.0, 0.0]))  # 0.6 + 0.4 >= 1.0
    assert not gate.step(0.3, np.array([1.0, 0.0, 0.2]))
    assert gate.step(0.4, np.array([1.0, 0.0, 0.05]))  # |0.2| + |-0.15| >= 0.25
    timed = UpdateGate(1.0, 0.25, 2.0)
    assert timed.step(0.0, np.zeros(3))
    assert not timed.step(2.0, np.zeros(3))
    assert timed.step(2.05, np.zeros(3))
    with pytest.raises(InputError, match="must not decrease"):
        timed.step(1.0, np.zeros(3))


def test_gate_wraps_rotation():
    gate = UpdateGate(1.0, 0.25, -1.0)
    gate.step(0.0, np.array([0.0, 0.0, 3.1]))
    assert not gate.step(0.1, np.array([0.0, 0.0, -3.1]))  # 0.083 rad across the +-pi cut
    assert math.isclose(gate.angular_rad, 2 * math.pi - 6.2, abs_tol=1e-9)


def test_every_scan_updates_with_zero_thresholds():
    laser = Laser(n_beams=5, angle_min=-0.2, angle_increment=0.1)
    slam = make_slam("odometry", laser, SlamParams(linear_update=0, angular_update=0))
    pose = np.array([1.0, 1.0, 0.0])
    assert all(slam.process(0.1 * k, pose, np.full(5, 2.0)) for k in range(5))


def test_bad_inputs_are_input_errors():
    laser = Laser(n_beams=5, angle_min=-0.2, angle_increment=0.1)
    with pytest.raises(InputError, match="unknown SLAM algorithm 'gmapping'"):
        make_slam("gmapping", laser)  # type: ignore[arg-type]
    slam = make_slam("odometry", laser)
    with pytest.raises(InputError, match="4 ranges, the laser 5"):
        slam.process(0.0, np.zeros(3), np.ones(4))
    with pytest.raises(InputError, match="3 finite numbers"):
        slam.process(0.0, np.array([0.0, np.nan, 0.0]), np.ones(5))
    with pytest.raises(InputError, match="particles must be >= 1"):
        SlamParams(particles=0)
    with pytest.raises(InputError, match="delta must be a positive"):
        SlamParams(delta=0.0)
    with pytest.raises(InputError, match="kernel_size must be <= 15"):
        SlamParams(kernel_size=16)  # the matcher reads a window row from at most two patches


def test_occupancy_is_cached_until_the_next_update():
    laser = Laser(n_beams=5, angle_min=-0.2, angle_increment=0.1)
    slam = make_slam("odometry", laser)
    assert slam.occupancy().known.sum() == 0  # before any scan: one unknown cell
    slam.process(0.0, np.array([1.0, 1.0, 0.0]), np.full(5, 2.0))
    g1 = slam.occupancy()
    assert slam.occupancy() is g1
    assert not slam.process(0.1, np.array([1.1, 1.0, 0.0]), np.full(5, 2.0))  # gated
    assert slam.occupancy() is g1
    assert slam.process(5.0, np.array([1.0, 2.5, 0.0]), np.full(5, 2.0))
    g2 = slam.occupancy()
    assert g2 is not g1 and g2.known.sum() > g1.known.sum()
