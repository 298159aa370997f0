"""Map cells written in place (protocol.cells_into): values by hand, and every malformed cell
refused, as the whole-map reader refused them before it wrote into views."""

from __future__ import annotations

import numpy as np
import pytest

from worker.slam.external.mapmsg import read_map
from worker.slam.external.protocol import ProtocolError, cells_into
from worker.slam.grid import OccupancyGrid


def _f32(values) -> bytes:
    return np.asarray(values, dtype="<f4").tobytes()


def test_float32_cells_keep_probabilities_and_make_negatives_unknown():
    out = np.full((2, 3), 7.0, dtype=np.float32)
    cells_into(out, _f32([[0.0, 0.25, 1.0], [np.nan, -1.0, -0.5]]), "float32", "map")
    want = np.array([[0.0, 0.25, 1.0], [np.nan, np.nan, np.nan]], dtype=np.float32)
    np.testing.assert_array_equal(out, want)


@pytest.mark.parametrize("bad", [1.5, np.inf, -np.inf])
def test_float32_cells_out_of_range_are_refused(bad):
    out = np.zeros((1, 2), dtype=np.float32)
    with pytest.raises(ProtocolError, match="patch 0 float32 cells must be probabilities"):
        cells_into(out, _f32([[0.5, bad]]), "float32", "patch 0")


def test_int8_cells_are_percentages_and_minus_one_unknown():
    out = np.zeros((1, 4), dtype=np.float32)
    cells_into(out, np.array([[-1, 0, 50, 100]], dtype="i1").tobytes(), "int8", "map")
    np.testing.assert_array_equal(out, np.array([[np.nan, 0.0, 0.5, 1.0]], dtype=np.float32))
    with pytest.raises(ProtocolError, match="int8 cells must be -1 or 0..100"):
        cells_into(out, np.array([[0, 101, 0, 0]], dtype="i1").tobytes(), "int8", "map")


def test_a_patch_writes_only_its_rectangle_of_a_view():
    prev = OccupancyGrid(np.zeros((3, 4), dtype=np.float32), 0.1, np.zeros(2))
    patch = {"col": 1, "row": 1, "width": 2, "height": 2, "data": _f32([[0.5, 1.0], [-1, 0.25]])}
    m = {"resolution": 0.1, "origin": [0.0, 0.0], "width": 4, "height": 3, "patches": [patch]}
    grid = read_map(m, prev, 0.25)
    want = np.zeros((3, 4), dtype=np.float32)
    want[1, 1:3], want[2, 1:3] = [0.5, 1.0], [np.nan, 0.25]
    np.testing.assert_array_equal(grid.prob, want)
    np.testing.assert_array_equal(prev.prob, np.zeros((3, 4)))  # the previous map untouched
    with pytest.raises(ProtocolError, match="map patch 0 'data' must be 16 bytes of float32"):
        read_map({**m, "patches": [{**patch, "data": b"\0" * 12}]}, prev, 0.25)
