"""Protocol version 2: maps as lists of changed cells, written over the previous map (in place
when nobody else holds it), and the map sent with the estimate it is read after."""

from __future__ import annotations

import weakref

import msgpack
import numpy as np
import pytest

from worker.slam.external import twin as twin_mod
from worker.slam.external.client import _sole_reference
from worker.slam.external.kernels import changed_cells, scatter
from worker.slam.external.mapmsg import read_map
from worker.slam.external.protocol import ProtocolError, unpack
from worker.slam.grid import OccupancyGrid

nan = np.nan


def _header(w: int, h: int, origin=(0.0, 0.0), res: float = 0.5, encoding: str = "float32"):
    return {"resolution": res, "origin": list(origin), "width": w, "height": h,
            "encoding": encoding}  # fmt: skip


def _cells(index, values, dtype="<f4") -> dict:
    return {
        "index": np.asarray(index, dtype="<u4").tobytes(),
        "data": np.asarray(values, dtype=dtype).tobytes(),
    }


def _grid(prob) -> OccupancyGrid:
    return OccupancyGrid(np.asarray(prob, dtype=np.float32), 0.5, np.zeros(2))


# --- kernels ---------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(30))
def test_changed_cells_lists_what_numpy_finds_in_a_window_of_the_map(seed):
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(1, 40, size=2))
    a = rng.random((h, w)).astype(np.float32)
    a[rng.random((h, w)) < 0.3] = nan  # NaN equals NaN by bit pattern: no change
    b = a.copy()
    for _ in range(rng.integers(0, 6)):
        b[rng.integers(h), rng.integers(w)] = rng.random()
    b[rng.random((h, w)) < 0.05] = nan  # cells that became unknown count too
    r0, c0 = int(rng.integers(0, h)), int(rng.integers(0, w))
    r1, c1 = int(rng.integers(r0 + 1, h + 1)), int(rng.integers(c0 + 1, w + 1))
    out = np.empty(h * w, dtype="<u4")
    ua, ub = a.view(np.uint32), b.view(np.uint32)
    n, *box = changed_cells(ub[r0:r1, c0:c1], ua[r0:r1, c0:c1], out, r0, c0, w)
    mask = np.zeros((h, w), dtype=bool)
    mask[r0:r1, c0:c1] = ua[r0:r1, c0:c1] != ub[r0:r1, c0:c1]
    np.testing.assert_array_equal(out[:n], np.flatnonzero(mask))
    if n:
        rows, cols = np.nonzero(mask)
        assert box == [rows.min(), rows.max() + 1, cols.min(), cols.max() + 1]
    else:
        assert box == [-1, -1, -1, -1]


def test_scatter_writes_probabilities_and_unknowns_or_nothing_at_all():
    out = np.zeros(5, dtype=np.float32)
    idx = np.array([4, 0, 2], dtype="<u4")
    assert scatter(idx, np.array([0.5, -1.0, nan], dtype="<f4"), out, False) == 0
    np.testing.assert_array_equal(out, [nan, 0, nan, 0, 0.5])
    out = np.zeros(4, dtype=np.float32)
    assert scatter(np.array([1, 3], dtype="<u4"), np.array([50, -1], "i1"), out, True) == 0
    np.testing.assert_array_equal(out, [0, 0.5, 0, nan])
    for index, values, is_int8 in (
        ([0, 4], np.array([0.5, 0.5], "<f4"), False),  # index 4 of 4 cells
        ([0, 1], np.array([0.5, 1.5], "<f4"), False),
        ([0, 1], np.array([0.5, -np.inf], "<f4"), False),
        ([0, 1], np.array([5, 101], "i1"), True),
    ):
        out = np.zeros(4, dtype=np.float32)
        assert scatter(np.array(index, dtype="<u4"), values, out, is_int8) != 0
        np.testing.assert_array_equal(out, 0)  # the good first cell was not written either


# --- reading version 2 maps ------------------------------------------------------------


def test_cells_are_written_over_the_previous_map_by_flat_index():
    prev = _grid([[0.0, 1.0, nan], [0.5, nan, 0.0]])
    m = {**_header(3, 2), "cells": _cells([2, 4], [0.75, 0.0])}  # (row 0, col 2), (1, 1)
    grid = read_map(m, prev, 0.25, version=2)
    np.testing.assert_array_equal(grid.prob, [[0.0, 1.0, 0.75], [0.5, 0.0, 0.0]])
    np.testing.assert_array_equal(prev.prob, [[0.0, 1.0, nan], [0.5, nan, 0.0]])  # a copy
    int8 = {**_header(3, 2, encoding="int8"), "cells": _cells([0], [-1], "i1")}
    assert np.isnan(read_map(int8, prev, 0.25, version=2).prob[0, 0])


def test_cells_land_in_a_grown_map_with_the_old_cells_moved():
    prev = _grid([[0.0, 1.0], [0.5, nan]])
    # one more column on the left: the old (0, 0) is now cell (row 0, col 1)
    m = {**_header(3, 2, (-0.5, 0.0)), "cells": _cells([0, 5], [0.25, 0.75])}
    grid = read_map(m, prev, 0.25, version=2)
    np.testing.assert_array_equal(grid.prob, [[0.25, 0.0, 1.0], [nan, 0.5, 0.75]])


def test_cells_need_version_2():
    prev = _grid([[0.0]])
    with pytest.raises(ProtocolError, match="'cells' needs protocol version 2"):
        read_map({**_header(1, 1), "cells": _cells([0], [0.5])}, prev, 0.25, version=1)
    with pytest.raises(ProtocolError, match="needs 'data' .* or 'patches' .*$"):
        read_map(_header(1, 1), prev, 0.25, version=1)
    with pytest.raises(ProtocolError, match="or 'cells' \\(version 2\\)"):
        read_map(_header(1, 1), prev, 0.25, version=2)


@pytest.mark.parametrize(
    ("cells", "needle"),
    [
        (_cells([0, 6], [0.5, 0.5]), "'index' holds a cell past the map's 6 cells"),
        (_cells([0, 1], [0.5, 1.5]), "float32 cells must be probabilities"),
        ({"index": b"\0" * 6, "data": b"\0" * 8}, "'index' must be bytes of uint32, got 6"),
        ({"index": b"\0" * 8, "data": b"\0" * 4}, "'data' must be 8 bytes of float32, got 4"),
        ({"index": [0], "data": b"\0" * 4}, "'index' must be bytes of uint32, got list"),
    ],
)
def test_a_malformed_cell_list_is_refused_and_the_previous_map_kept_whole(cells, needle):
    prev = OccupancyGrid.adopt(np.zeros((2, 3), dtype=np.float32), 0.5, np.zeros(2))
    with pytest.raises(ProtocolError, match=needle):
        read_map({**_header(3, 2), "cells": cells}, prev, 0.25, version=2, reuse=True)
    np.testing.assert_array_equal(prev.prob, 0)
    assert not prev.prob.flags.writeable


def test_a_bad_second_patch_leaves_the_reused_map_untouched():
    prev = OccupancyGrid.adopt(np.zeros((2, 2), dtype=np.float32), 0.5, np.zeros(2))
    good = {"col": 0, "row": 0, "width": 1, "height": 1, "data": np.float32(0.5).tobytes()}
    bad = {**good, "col": 1, "data": np.float32(2.0).tobytes()}
    with pytest.raises(ProtocolError, match="map patch 1 float32 cells must be"):
        read_map({**_header(2, 2), "patches": [good, bad]}, prev, 0.25, reuse=True)
    np.testing.assert_array_equal(prev.prob, 0)


def test_reuse_writes_into_the_previous_cells_only_for_the_same_extent():
    prev = OccupancyGrid.adopt(np.zeros((2, 3), dtype=np.float32), 0.5, np.zeros(2))
    cells = prev.prob
    grid = read_map({**_header(3, 2), "cells": _cells([1], [1.0])}, prev, 0.25, version=2,
                    reuse=True)  # fmt: skip
    assert grid.prob is cells and grid.prob[0, 1] == 1.0 and not cells.flags.writeable
    grown = read_map({**_header(4, 2), "cells": _cells([0], [1.0])}, grid, 0.25, version=2,
                     reuse=True)  # fmt: skip
    assert grown.prob is not cells and grown.shape == (2, 4)


def test_only_a_grid_nobody_else_holds_is_reused():
    class Holder:
        pass

    def alone() -> bool:  # called apart from `assert`: pytest's rewriting keeps its operands
        return _sole_reference(h.grid)

    h = Holder()
    h.grid = OccupancyGrid.adopt(np.zeros((2, 2), dtype=np.float32), 0.5, np.zeros(2))
    ok = alone()
    assert ok
    kept = h.grid
    ok = alone()
    assert not ok
    del kept
    cells = h.grid.prob
    ok = alone()
    assert not ok
    del cells
    row = h.grid.prob[1]  # a view holds its base
    ok = alone()
    assert not ok
    del row
    ok = alone()
    assert ok


# --- the twin's side -------------------------------------------------------------------


def _replay(sender: twin_mod.MapSender, grids, withins) -> list[np.ndarray]:
    """What mapqual reads from `sender`'s messages for `grids`, one after the other."""
    got, prev = [], None
    for grid, within in zip(grids, withins, strict=True):
        m = sender.message(grid, within)
        if m is not None:  # over the wire: msgpack's bytes
            m = unpack(msgpack.packb({"type": "map", "map": m}, use_bin_type=True))["map"]
            prev = read_map(m, prev, 0.25, version=sender.version)
        got.append(prev.prob.copy())
    return got


def test_the_twin_sends_cells_a_box_or_the_whole_map_and_mapqual_rebuilds_each_map():
    rng = np.random.default_rng(3)
    base = np.full((40, 60), nan, dtype=np.float32)
    base[5:35, 5:55] = 0.0
    grids = [OccupancyGrid(base, 0.05, np.zeros(2))]
    few = base.copy()
    few[[6, 30], [7, 50]] = 0.9  # two cells far apart: a list, not a 25 x 44 box
    grids.append(OccupancyGrid(few, 0.05, np.zeros(2)))
    many = few.copy()
    many[10:20, 10:20] = rng.random((10, 10)).astype(np.float32)  # a dense block: the box
    grids.append(OccupancyGrid(many, 0.05, np.zeros(2)))
    grown = np.full((40, 70), nan, dtype=np.float32)  # ten columns more on the left
    grown[:, 10:] = many
    grown[0, 0] = grown[39, 69] = 0.5  # two corners: a list
    grids.append(OccupancyGrid(grown, 0.05, np.array([-0.5, 0.0])))
    grids.append(OccupancyGrid(grown, 0.05, np.array([-0.5, 0.0])))  # unchanged: None
    sender = twin_mod.MapSender(2)
    kinds = []
    for g in grids:
        m = sender.message(g)
        kinds.append(None if m is None else next(k for k in ("data", "patches", "cells") if k in m))
    assert kinds == ["data", "cells", "patches", "cells", None]
    for version in (1, 2):
        got = _replay(twin_mod.MapSender(version), grids, [None] * len(grids))
        for want, have in zip(grids, got, strict=True):
            np.testing.assert_array_equal(have, want.prob)


def test_the_twin_compares_only_where_its_scans_reached_and_finds_the_same_cells():
    """An odometry map fed the scans of a robot in a box: for every update, the cells listed
    when comparing only the box the scans reached are those of comparing everything."""
    from tests.worker.slam.external.test_client import LASER, _scans
    from worker.slam.odometry import OdometrySlam
    from worker.slam.params import SlamParams

    params = SlamParams(linear_update=0.0, angular_update=0.0)
    slam = OdometrySlam(LASER, params)
    reach = twin_mod._Reach(twin_mod._Laser(_laser_dict()), params)
    grids, withins = [], []
    for t, pose, ranges in _scans(25):
        assert slam.process(t, pose, ranges)
        reach.add(pose, ranges)
        grids.append(slam.occupancy())
        withins.append(reach.take())
    boxed = _replay(twin_mod.MapSender(2), grids, withins)
    for want, have in zip(grids, boxed, strict=True):
        np.testing.assert_array_equal(have, want.prob)
    small = [w for w in withins[1:] if (w[2] - w[0]) * (w[3] - w[1]) < 4.5 * 4.5]
    assert len(small) == len(withins) - 1  # the 4 m box the robot sees, not the whole map


def _laser_dict() -> dict:
    from tests.worker.slam.external.test_client import LASER

    return {"n_beams": LASER.n_beams, "angle_min": LASER.angle_min,
            "angle_increment": LASER.angle_increment, "range_max": LASER.range_max}  # fmt: skip


def test_a_step_with_map_due_gets_its_map_with_the_estimate():
    tw = twin_mod.Twin("odometry")
    assert tw.answer({"type": "hello", "versions": [1, 2]})["version"] == 2
    ready = tw.answer({"type": "config", "laser": _laser_dict(), "params": {}, "seed": 0})
    assert "gate" in ready
    ranges = np.full(_laser_dict()["n_beams"], 3.0).tobytes()
    step = {"type": "step", "seq": 0, "t": 0.0, "odom": [0.0, 0.0, 0.0], "ranges": ranges}
    first = tw.answer({**step, "map_due": True})
    assert first["updated"] and "data" in first["map"]
    second = tw.answer({**step, "seq": 1, "t": 0.1, "odom": [0.2, 0.0, 0.0]})
    assert second["updated"] and "map" not in second  # asked for later, if read
    assert tw.answer({"type": "map"})["map"] is not None


@pytest.mark.parametrize("version", [1, 2])
def test_map_due_goes_only_to_a_version_2_program_and_only_when_the_map_will_be_read(version):
    from tests.worker.slam.external.helpers import fake
    from tests.worker.slam.external.test_client import _scans, _slam

    slam = _slam(fake(f"due{version}"))
    try:
        for k, (t, pose, ranges) in enumerate(_scans(4)):
            slam.will_read_map(k % 2 == 1)  # the exploration reads the map after scans 1, 3
            assert slam.process(t, pose, ranges)
            if k % 2 == 1:
                slam.occupancy()
        log = slam._child.stderr_tail().splitlines()
    finally:
        slam.close()
    v2 = version == 2
    assert slam.version == version
    assert [line for line in log if line.startswith("due")] == [
        "due 0 false", f"due 1 {'true' if v2 else 'false'}", "due 2 false",
        f"due 3 {'true' if v2 else 'false'}",
    ]  # fmt: skip
    # no map came with those estimates here, so mapqual asked for it: once per read
    assert log.count("map request") == 2


def test_a_map_kept_by_the_caller_is_never_written_over():
    """Through the twin: maps read and let go are rewritten in place; one kept stays as it
    was when read, while the maps after it still match the in-process algorithm's."""
    from dataclasses import replace

    from tests.worker.slam.external.helpers import twin
    from tests.worker.slam.external.test_client import LASER, _scans
    from worker.slam.external.client import ExternalSlam
    from worker.slam.external.params import ExternalSlamParams
    from worker.slam.odometry import OdometrySlam
    from worker.slam.params import SlamParams

    params = SlamParams(linear_update=0.2, angular_update=0.2)
    local = OdometrySlam(LASER, params)
    ext = ExternalSlamParams("twin", tuple(twin("odometry")))
    remote = ExternalSlam(LASER, replace(params, external=ext), np.random.default_rng(0))
    kept, kept_copy, last, in_place = None, None, None, 0
    with remote:
        for t, pose, ranges in _scans(25):
            remote.will_read_map(True)
            if remote.process(t, pose, ranges) | local.process(t, pose, ranges):
                grid = remote.occupancy()
                np.testing.assert_array_equal(grid.prob, local.occupancy().prob)
                in_place += last is not None and grid.prob is last()
                if kept is None and t >= 1.0:
                    kept, kept_copy = grid, grid.prob.copy()
                last = weakref.ref(grid.prob)  # no reference: the grid may be reused
                del grid
        assert remote.version == 2 and remote.updates > 8
    np.testing.assert_array_equal(kept.prob, kept_copy)
    assert not kept.prob.flags.writeable
    assert in_place >= 3  # rewritten in place while nobody kept them


@pytest.mark.parametrize("form", ["patches", "cells"])
def test_a_map_too_large_to_allocate_is_refused_before_anything_is_allocated(form):
    """A program claiming a 10^6 x 10^6 map (4 TB of float32) with an empty patch list or
    cell list: a protocol error, not a worker killed by the memory it asked for."""
    body = {"patches": []} if form == "patches" else {"cells": _cells([], [])}
    m = {**_header(1_000_000, 1_000_000), **body}
    with pytest.raises(ProtocolError, match="a map of 1000000 x 1000000 cells is larger"):
        read_map(m, _grid([[0.0]]), 0.25, version=2)
    largest = 8192 * 8192  # 64 Mi cells: a whole int8 map in one 64 MiB frame
    ok = {**_header(8192, 8192), "cells": _cells([largest - 1], [0.5])}
    assert read_map(ok, None, 0.25, version=2).prob[-1, -1] == 0.5
