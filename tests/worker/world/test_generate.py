"""Generated large buildings: seeded, closed, connected for the robot, rooms of one size."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from worker.errors import InputError
from worker.world.generate import BuildingSpec, generate, write_world
from worker.world.loader import load_world

RES = 0.05  # [m/pixel]


def _free(img: np.ndarray) -> np.ndarray:
    return img >= 250


@pytest.mark.parametrize("kind", ["warehouse", "hospital"])
def test_same_seed_same_plan_other_seed_other_plan(kind):
    a = generate(BuildingSpec(kind, 80.0, 50.0, seed=3))
    b = generate(BuildingSpec(kind, 80.0, 50.0, seed=3))
    c = generate(BuildingSpec(kind, 80.0, 50.0, seed=4))
    assert a.shape == (1000, 1600)  # 50 m x 80 m at 0.05 m/pixel
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("kind", ["warehouse", "hospital"])
@pytest.mark.parametrize("seed", [1, 2, 7])
def test_closed_and_every_free_cell_reachable_by_the_robot(kind, seed):
    img = generate(BuildingSpec(kind, 70.0, 45.0, seed=seed))
    free = _free(img)
    assert not free[0].any() and not free[-1].any()  # the outer wall closes the building
    assert not free[:, 0].any() and not free[:, -1].any()
    _, n = ndimage.label(free)
    assert n == 1
    # the robot's centre keeps 0.2 m (half its 0.4 m footprint) from walls: the free space
    # shrunk by that much must still be one piece, or some room cannot be driven into
    half = round(0.2 / RES)
    centre_free = ndimage.binary_erosion(free, np.ones((2 * half + 1, 2 * half + 1), bool))
    _, n_centre = ndimage.label(centre_free)
    assert n_centre == 1


def test_hospital_is_many_identical_rooms_off_corridors():
    img = generate(BuildingSpec("hospital", 60.0, 40.0, seed=5))
    # doors are 1.0 m wide, corridors 2.4 m: shrinking the free space by 0.55 m on each side
    # cuts every door and keeps every room and corridor, so pieces = rooms + corridor network.
    # By hand: two wards of 13.8 m fit in 39.4 m, each with two rows of rooms of 3.6-4.4 m
    # (+0.2 m walls) along 53 m: 4 rows of 11, 12 or 14 slots (53.2 / 4.6, 4.2 or 3.8), a few
    # slot pairs joined into double rooms (8 % of the time each).
    k = 2 * round(0.55 / RES) + 1
    pieces, n = ndimage.label(ndimage.binary_erosion(_free(img), np.ones((k, k), bool)))
    areas = np.bincount(pieces.ravel())[1:]
    corridor = int(np.argmax(areas))
    rooms = np.delete(areas, corridor)
    assert 33 <= len(rooms) <= 56
    values, counts = np.unique(rooms, return_counts=True)
    assert counts.max() >= 0.7 * len(rooms)  # most rooms are the same room


def _runs(mask: np.ndarray) -> np.ndarray:
    """Lengths of the runs of True in a 1-D mask."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return edges[1::2] - edges[0::2]


def test_warehouse_has_racks_with_aisles_between():
    img = generate(BuildingSpec("warehouse", 120.0, 60.0, seed=2))
    free = _free(img)
    # a column at x = 110 m, beyond the last cross aisle (none within 10 m of the racks' end at
    # 114.7 m) and far from the office block in the other corner; cut at y = 50 m, above the
    # dock strip and its pallets: the outer wall, the main aisle, then racks of 2.2 m with
    # aisles of 2.8-3.6 m between them down to the dock area
    col = free[: int(50.0 / RES), int(110.0 / RES)]
    racks = _runs(~col)[1:] * RES
    aisles = _runs(col)[1:-1] * RES
    assert len(racks) >= 5 and np.allclose(racks, 2.2, atol=0.051)
    assert np.all((aisles > 2.75) & (aisles < 3.65))
    assert np.ptp(aisles) < 0.06  # one aisle width throughout the building


def test_written_world_loads_as_one_region(tmp_path):
    spec = BuildingSpec("hospital", 50.0, 35.0, seed=1)
    path = write_world(generate(spec), spec, tmp_path, "wing")
    world = load_world(path)
    assert world.facts.width_m == pytest.approx(50.0)
    assert world.facts.height_m == pytest.approx(35.0)
    assert world.facts.n_free_regions == 1
    x, y, _ = world.start_pose
    assert 0 < x < 50 and 0 < y < 35


@pytest.mark.parametrize(
    "spec, words",
    [
        (BuildingSpec("castle", 100, 100), "unknown building kind"),  # type: ignore[arg-type]
        (BuildingSpec("warehouse", 10, 100), "below"),
        (BuildingSpec("warehouse", float("nan"), 100), "below"),
        (BuildingSpec("warehouse", 2000, 2000), "exceed"),
        (BuildingSpec("hospital", 100, 100, resolution=0.0), "resolution"),
    ],
)
def test_bad_specs_are_refused_in_one_line(spec, words):
    with pytest.raises(InputError, match=words):
        generate(spec)
