"""The viewer's scene layers on a real viser server: map tiles composited over the floorplan
and re-sent only where a patch touched them; paths that grow by chunks and merge."""

from __future__ import annotations

import numpy as np
import pytest

from frontend.layers import (
    BACKGROUND,
    FLOOR_FREE,
    FLOOR_WALL,
    MAP_FREE_RGB,
    MAP_OCC_RGB,
    MAX_CHUNKS,
    TILE,
    Floorplan,
    MapTiles,
    PathLayer,
)
from tests.frontend.conftest import free_port
from worker.live_wire import FREE, OCCUPIED, UNKNOWN


@pytest.fixture(scope="module")
def scene():
    import viser

    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield server.scene
    server.stop()


def test_tiles_show_the_floorplan_under_unknown_cells(scene):
    occ = np.zeros((20, 30), bool)
    occ[:, 0] = True  # a wall along x in [0, 0.1) m
    floor = Floorplan(scene, "/t1/floor", occ, 0.1, (0.0, 0.0))
    tiles = MapTiles(scene, "/t1/map")
    tiles.floor = floor
    codes = np.full((4, 4), UNKNOWN, np.uint8)
    codes[0, 1] = FREE
    codes[0, 2] = OCCUPIED
    # map cells of 0.05 m from (-0.05, 0): column 0 lies outside the plan, column 1 on the wall
    rgb = tiles._rgb(codes, 0.05, -0.05, 0.0)  # bottom row first, as viser draws images
    assert rgb[1, 0].tolist() == [BACKGROUND] * 3
    assert rgb[1, 1].tolist() == [FLOOR_WALL] * 3
    assert rgb[1, 3].tolist() == [FLOOR_FREE] * 3
    assert rgb[0, 1].tolist() == ((FLOOR_WALL + MAP_FREE_RGB) // 2).tolist()
    assert rgb[0, 2].tolist() == MAP_OCC_RGB.tolist()
    tiles.floor_on = False
    assert tiles._rgb(codes, 0.05, -0.05, 0.0)[1, 1].tolist() == [BACKGROUND] * 3


def test_a_patch_resends_only_the_tiles_it_touches(scene):
    tiles = MapTiles(scene, "/t2/map")
    codes = np.full((2 * TILE, 3 * TILE), FREE, np.uint8)
    tiles.show(codes, 0.05, (0.0, 0.0))
    assert tiles.n_tiles() == 6
    before = {k: (n, n._data) for k, n in tiles.tiles.items()}
    codes[TILE + 3, 2 * TILE + 5] = OCCUPIED
    tiles.show(codes, 0.05, (0.0, 0.0), (TILE + 3, 2 * TILE + 5, 1, 1))
    # the touched tile gets new pixels in its node (kept: no blank frame while they decode)
    changed = [k for k, (n, data) in before.items() if tiles.tiles[k]._data is not data]
    assert changed == [(1, 2)] and all(tiles.tiles[k] is n for k, (n, _) in before.items())
    tiles.show(np.zeros((10, 10), np.uint8), 0.05, (1.0, 0.0))  # a new map: all replaced
    assert tiles.n_tiles() == 0


def test_paths_grow_by_chunks_and_merge(scene):
    path = PathLayer(scene, "/t3/gt", (0, 200, 0), 0.05)
    pts = np.cumsum(np.ones((3 * MAX_CHUNKS + 1, 2)), axis=0)
    path.append(pts[:1])
    assert path.nodes == []  # one point is no line yet
    for i in range(1, len(pts)):
        path.append(pts[i : i + 1])
        assert 1 <= len(path.nodes) <= MAX_CHUNKS
    np.testing.assert_array_equal(path.points, pts)
    # every segment of the polyline is drawn exactly once across the nodes
    drawn = sum(len(n.points) for n in path.nodes)
    merged = [n for n in path.nodes if len(n.points) > 1]
    assert drawn == len(pts) - 1 and len(merged) == 1
    path.set(pts[:5])
    assert len(path.nodes) == 1 and len(path.nodes[0].points) == 4
