"""The twin's changed-cell box against numpy's argwhere on random maps, and a grid that adopts
its cells without a copy."""

from __future__ import annotations

import numpy as np
import pytest

from worker.slam.external.kernels import changed_box
from worker.slam.grid import OccupancyGrid


def _box_by_argwhere(a: np.ndarray, b: np.ndarray) -> tuple[int, int, int, int]:
    where = np.argwhere(a.view(np.uint32) != b.view(np.uint32))
    if where.size == 0:
        return -1, -1, -1, -1
    (r0, c0), (r1, c1) = where.min(axis=0), where.max(axis=0)
    return int(r0), int(r1) + 1, int(c0), int(c1) + 1


@pytest.mark.parametrize("seed", range(40))
def test_the_changed_box_is_the_bounding_box_of_the_changed_cells(seed):
    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 60, size=2)
    a = rng.random((h, w)).astype(np.float32)
    a[rng.random((h, w)) < 0.3] = np.nan  # unknown cells: NaN equals NaN by bit pattern
    b = a.copy()
    for _ in range(rng.integers(0, 4)):  # a few changed cells, anywhere, edges included
        b[rng.integers(h), rng.integers(w)] = rng.random()
    got = changed_box(a.view(np.uint32), b.view(np.uint32))
    assert tuple(int(v) for v in got) == _box_by_argwhere(a, b)


def test_an_unchanged_map_with_unknown_cells_has_no_box():
    a = np.full((5, 7), np.nan, dtype=np.float32)
    assert changed_box(a.view(np.uint32), a.copy().view(np.uint32))[0] == -1


def test_a_grid_adopts_fresh_cells_read_only_and_copies_anything_else():
    prob = np.zeros((3, 4), dtype=np.float32)
    grid = OccupancyGrid.adopt(prob, 0.05, np.array([1.0, 2.0]))
    assert grid.prob is prob and not prob.flags.writeable
    assert grid.resolution == 0.05 and grid.origin.tolist() == [1.0, 2.0]
    as_float64 = np.zeros((3, 4))
    copied = OccupancyGrid.adopt(as_float64, 0.05, np.zeros(2))
    assert copied.prob.dtype == np.float32 and copied.prob is not as_float64
