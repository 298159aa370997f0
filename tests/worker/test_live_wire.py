"""The live feed's wire format: cell codes from a grid's thresholds and from a stored ROS
grid, changed rectangles, map patches that survive JSON, scan end points in the world frame."""

from __future__ import annotations

import json

import numpy as np

from worker.live_wire import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    changed_box,
    decode_map_patch,
    encode_map_patch,
    map_codes,
    ros_codes,
    scan_points,
    thin,
)
from worker.pipeline import RunProgress
from worker.slam.grid import OccupancyGrid


def test_map_codes_follow_the_grid_thresholds():
    prob = np.array([[np.nan, 0.0, 0.25], [0.26, 1.0, np.nan]], dtype=np.float32)
    codes = map_codes(OccupancyGrid(prob, 0.05, (0.0, 0.0)))
    assert codes.tolist() == [[UNKNOWN, FREE, FREE], [OCCUPIED, OCCUPIED, UNKNOWN]]


def test_changed_box_is_the_bounding_box_of_the_differences():
    rng = np.random.default_rng(3)
    for _ in range(50):
        a = rng.integers(0, 3, (40, 60)).astype(np.uint8)
        b = a.copy()
        cells = rng.integers(0, [40, 60], (rng.integers(0, 5), 2))
        for iy, ix in cells:
            b[iy, ix] = (b[iy, ix] + 1) % 3
        box = changed_box(a, b)
        if len(cells) == 0:
            assert box is None
            continue
        iy0, ix0, h, w = box
        assert (iy0, ix0) == (cells[:, 0].min(), cells[:, 1].min())
        assert (iy0 + h - 1, ix0 + w - 1) == (cells[:, 0].max(), cells[:, 1].max())


def test_map_patch_round_trip():
    codes = np.random.default_rng(0).integers(0, 3, (30, 50)).astype(np.uint8)
    msg = json.loads(json.dumps(encode_map_patch(codes, (5, 7, 10, 20), 0.05, (1.0, -2.0), False)))
    box, patch = decode_map_patch(msg)
    assert box == (5, 7, 10, 20) and msg["shape"] == [30, 50] and msg["origin"] == [1.0, -2.0]
    np.testing.assert_array_equal(patch, codes[5:15, 7:27])


def _progress(pose, ranges, angles) -> RunProgress:
    pose = np.asarray(pose, dtype=float)
    return RunProgress(
        0.0, 0.5, pose, pose, "driving", 0, 0.0, 1.0, ranges=ranges, beam_angles=angles,
        range_max=30.0,
    )  # fmt: skip


def test_scan_points_drop_no_return_beams_and_lie_at_the_range():
    angles = np.array([-np.pi / 2, 0.0, np.pi / 2])
    p = _progress([1.0, 2.0, np.pi / 2], np.array([1.0, 30.0, 2.0]), angles)
    # heading +90 deg: beam -90 points along +x, beam +90 along -x; the 30 m beam is dropped
    np.testing.assert_allclose(scan_points(p), [[2.0, 2.0], [-1.0, 2.0]], atol=1e-12)


def test_ros_codes_follow_map_savers_thresholds():
    # map_saver: -1 unknown; occupied from 65 (its default occupied threshold 0.65)
    grid = np.array([[-1, 0, 64], [65, 100, -1]], dtype=np.int8)
    assert ros_codes(grid).tolist() == [[UNKNOWN, FREE, FREE], [OCCUPIED, OCCUPIED, UNKNOWN]]
    assert ros_codes(grid).dtype == np.uint8


def test_thin_keeps_at_most_that_many_points_and_the_last():
    pts = np.arange(1000, dtype=float).reshape(-1, 2)  # 500 points
    out = thin(pts, 200)
    assert len(out) <= 200 and out[0].tolist() == [0.0, 1.0] and out[-1].tolist() == [998.0, 999.0]
    assert np.all(np.diff(out[:, 0]) > 0)  # in order, none twice
    np.testing.assert_array_equal(thin(pts[:5], 200), pts[:5])  # fewer: all of them
