"""Floorplan features on hand-built plans whose values follow from geometry, and on Bormann
plans against their ground-truth room segmentation."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from worker.errors import InputError
from worker.world import load_world
from worker.world.features import features_of, world_features
from worker.world.world import World

RES = 0.05  # [m/cell]
BORMANN = Path(__file__).resolve().parents[3] / "worlds" / "bormann"


def boxed(h: int, w: int) -> np.ndarray:
    """(h, w) free cells inside a one-cell wall: free interior (h-2) x (w-2) cells."""
    occ = np.zeros((h, w), bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    return occ


def room_grid(n: int, room: int) -> np.ndarray:
    """(n, n) cells: square rooms `room` cells a side, one-cell walls, a 1 m door (20 cells)
    in the middle of every wall."""
    occ = boxed(n, n)
    for k in range(room, n - 1, room):
        occ[k, :] = True
        occ[:, k] = True
    for k in range(room, n - 1, room):
        for s in range(0, n - room + 1, room):
            mid = s + room // 2
            occ[k, mid - 10 : mid + 10] = False
            occ[mid - 10 : mid + 10, k] = False
    return occ


def test_empty_room_area_perimeter_openness_and_topology():
    occ = boxed(162, 242)  # interior 160 x 240 cells = 8 m x 12 m
    f = world_features(World.from_array(occ, RES))
    assert f.free_area_m2 == pytest.approx(8 * 12)
    assert f.perimeter_m == pytest.approx(2 * (8 + 12))
    assert f.perimeter_per_area == pytest.approx(40 / 96)
    # a convex room 14.4 m across: a 30 m laser sees all of it from anywhere (up to the work
    # grid's coarsening and the 360-ray polygon, each well under 3 %)
    assert f.openness_m2 == pytest.approx(96, rel=0.05)
    assert f.openness_share == pytest.approx(1.0, rel=0.05)
    assert (f.n_rooms, f.graph_cycles, f.clutter_share, f.clutter_islands_per_100m2) == (
        1, 0, 0.0, 0.0,
    )  # fmt: skip
    assert f.rooms_from == "clearance"
    # a rectangle's clearance is at most half its short side
    assert f.clearance_p90_m <= 4.0 and f.clearance_p10_m < f.clearance_p50_m


def test_pillar_makes_one_loop_and_one_island():
    occ = boxed(162, 162)  # 8 m x 8 m
    occ[70:90, 70:90] = True  # a 1 m x 1 m pillar in the middle
    f = world_features(World.from_array(occ, RES))
    assert f.graph_cycles == 1
    assert f.clutter_islands_per_100m2 == pytest.approx(100 / (64 - 1))
    assert f.clutter_share == pytest.approx(1 / 64, rel=0.1)  # pillar / outline, coarsened
    assert f.free_area_m2 == pytest.approx(63)


def test_ring_corridor_longest_path_is_half_the_loop():
    occ = boxed(222, 222)  # 11 m outside, a 1 m wide ring corridor around a 9 m block
    occ[21:201, 21:201] = True
    f = world_features(World.from_array(occ, RES))
    assert f.graph_cycles == 1
    # the centre line is a 10 m square: 40 m around; the farthest point along it is 20 m away
    assert f.medial_axis_m == pytest.approx(40, rel=0.08)
    assert f.graph_longest_path_m == pytest.approx(20, rel=0.08)


def test_straight_corridor_is_a_corridor_of_its_length():
    occ = boxed(42, 402)  # 2 m x 20 m
    f = world_features(World.from_array(occ, RES))
    assert f.corridor_share == pytest.approx(1.0)
    assert f.longest_corridor_m == pytest.approx(20, rel=0.03)  # rectangle's long side
    assert f.graph_longest_path_m == pytest.approx(20, rel=0.1)
    assert f.graph_cycles == 0


def test_two_identical_rooms_are_repeats():
    occ = boxed(122, 243)  # two 6 m x 6 m rooms, a wall between them with a 1 m door
    occ[:, 121] = True
    occ[50:70, 121] = False
    f = world_features(World.from_array(occ, RES))
    assert f.n_rooms == 2
    assert f.room_area_mean_m2 == pytest.approx(36, rel=0.05)
    assert f.repeated_room_share == 1.0
    assert f.corridor_share == 0.0


@pytest.mark.parametrize("name", ["office_a", "lab_ipa"])
def test_own_segmentation_finds_the_ground_truth_rooms(name):
    # Bormann et al.'s hand-made segmentation is independent of our clearance watershed
    w = load_world(BORMANN / f"{name}.yaml")
    assert w.facts.n_rooms is not None
    own = world_features(w)
    assert own.rooms_from == "clearance"
    assert abs(own.n_rooms - w.facts.n_rooms) <= max(2, 0.1 * w.facts.n_rooms)
    gt = features_of(w)
    assert gt.rooms_from == "segmentation" and gt.n_rooms == w.facts.n_rooms


def test_furniture_raises_clutter_and_lowers_openness():
    bare = features_of(load_world(BORMANN / "office_a.yaml"))
    furnished = features_of(load_world(BORMANN / "office_a_furnitures.yaml"))
    assert furnished.clutter_islands_per_100m2 > 5 * bare.clutter_islands_per_100m2
    assert furnished.openness_m2 < bare.openness_m2
    assert furnished.clearance_mean_m < bare.clearance_mean_m


def test_no_enclosed_free_space_is_refused():
    occ = np.zeros((60, 60), bool)  # free everywhere: the border touches free space
    with pytest.raises(InputError, match="no enclosed free space"):
        world_features(World.from_array(occ, RES))


def test_features_are_deterministic_and_fast_on_a_2000_cell_plan():
    w = World.from_array(room_grid(2000, 200), RES)  # 100 m x 100 m, 100 rooms of 10 m
    world_features(w)  # compile / warm up
    t0 = time.process_time()
    a = world_features(w)
    cpu = time.process_time() - t0
    assert a == world_features(w)
    assert cpu < 1.0, f"{cpu:.2f} s of CPU"
    assert a.free_area_m2 == pytest.approx(100 * 100, rel=0.03)  # less the walls
    assert a.n_rooms == 100 and a.repeated_room_share == 1.0
    assert math.isfinite(a.openness_m2)
