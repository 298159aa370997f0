"""World.from_array: facts against hand-counted grids, start pose choice, validation."""

from __future__ import annotations

import math

import numpy as np
import pytest

from worker.errors import InputError
from worker.world import World

RES = 0.05


def two_rooms() -> np.ndarray:
    """A 4 m x 2 m room (wall 1 cell) and, apart from it, a closed 1 m x 1 m room."""
    occ = np.ones((60, 140), dtype=bool)
    occ[1:41, 1:81] = False  # 80 x 40 free cells = 4.0 m x 2.0 m
    occ[45:65, 100:120] = False  # 20 x 15 cells (rows 45..59): 1.0 m x 0.75 m
    return occ


def test_facts_match_hand_counts():
    world = World.from_array(two_rooms(), RES, origin=(-1.0, 2.0), name="two")
    f = world.facts
    assert (f.width_px, f.height_px) == (140, 60)
    assert world.width_m == pytest.approx(7.0) and world.height_m == pytest.approx(3.0)
    assert f.free_area_m2 == pytest.approx(80 * 40 * RES**2 + 20 * 15 * RES**2)
    assert f.free_fraction == pytest.approx((3200 + 300) / (140 * 60))
    assert f.n_free_regions == 2
    # The small room touches the top border: the big one is the largest ENCLOSED region.
    assert f.largest_region_area_m2 == pytest.approx(8.0)
    assert f.largest_region_share == pytest.approx(3200 / 3500)
    assert f.main_region_enclosed and f.border_free
    assert any("border" in w for w in world.warnings)
    # Clearance in the 2 m wide room peaks at its middle rows: 20 cells to the wall centre
    # line minus half a cell -> 0.975 m.
    assert f.clearance_max_m == pytest.approx(0.975)


def test_start_pose_is_the_cell_of_largest_clearance_in_the_main_region():
    world = World.from_array(two_rooms(), RES, origin=(-1.0, 2.0))
    x, y, theta = world.start_pose
    ix, iy = world.world_to_cell(x, y)
    assert 1 <= ix <= 80 and 1 <= iy <= 40  # in the big room
    assert world.clearance[iy, ix] == pytest.approx(world.facts.clearance_max_m)
    assert theta == 0.0
    # Cell centres: origin + (i + 0.5) * res.
    assert (x + 1.0) / RES % 1.0 == pytest.approx(0.5)
    assert (y - 2.0) / RES % 1.0 == pytest.approx(0.5)


def test_an_enclosed_building_is_preferred_over_free_space_outside_it():
    occ = np.zeros((200, 200), dtype=bool)  # free all around (outside the building)
    occ[50:150, 50:150] = True
    occ[52:148, 52:148] = False  # the building's interior, enclosed by a 2-cell wall
    world = World.from_array(occ, RES)
    ix, iy = world.world_to_cell(*world.start_pose[:2])
    assert 52 <= ix < 148 and 52 <= iy < 148
    assert world.facts.main_region_enclosed


def test_a_given_start_pose_is_kept_and_its_angle_wrapped():
    world = World.from_array(two_rooms(), RES, start_pose=(1.0, 1.0, 3 * math.pi))
    np.testing.assert_allclose(world.start_pose, [1.0, 1.0, -math.pi])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"resolution": 0.005}, "resolution 0.005 m/pixel is outside"),
        ({"resolution": 1.5}, "outside"),
        ({"start_pose": (-3.0, 0.0, 0.0)}, "not on a free cell"),
        ({"start_pose": (0.0, float("nan"), 0.0)}, "finite"),
        ({"origin": (0.0, float("inf"))}, "origin must be two finite numbers"),
        ({"origin": (1.0, 2.0, 3.0)}, "origin must be two finite numbers"),
    ],
)
def test_validation_errors(kwargs, message):
    args = {"occ": two_rooms(), "resolution": RES} | kwargs
    with pytest.raises(InputError, match=message):
        World.from_array(**args)


def test_no_room_for_the_footprint():
    occ = np.ones((40, 40), dtype=bool)
    occ[5:35, 10:18] = False  # an 8-cell = 0.4 m wide corridor: the robot cannot turn
    with pytest.raises(InputError, match="no free space wide enough"):
        World.from_array(occ, RES)
    with pytest.raises(InputError, match="no free cell"):
        World.from_array(np.ones((10, 10), dtype=bool), RES)


def test_grid_is_read_only_and_bottom_row_first():
    occ = np.zeros((30, 30), dtype=bool)
    occ[0, :] = True  # bottom row (y in [0, 0.05))
    world = World.from_array(occ, RES)
    assert not world.occ.flags.writeable
    assert not world.is_free(0.5, 0.02) and world.is_free(0.5, 0.2)
