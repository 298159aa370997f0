"""The protocol's framing and map messages, against hand-written bytes and hand-made grids."""

from __future__ import annotations

import struct

import msgpack
import numpy as np
import pytest

from worker.slam.external import protocol as proto
from worker.slam.external.mapmsg import read_map
from worker.slam.grid import OccupancyGrid


def test_a_frame_is_a_big_endian_length_then_the_msgpack_map():
    data = proto.frame({"type": "bye"})
    # msgpack by hand: fixmap of 1 (0x81), fixstr "type" (0xa4 ...), fixstr "bye" (0xa3 ...)
    payload = b"\x81\xa4type\xa3bye"
    assert data == b"\x00\x00\x00\x0a" + payload
    assert proto.unpack(payload) == {"type": "bye"}


def test_a_step_carries_the_ranges_as_little_endian_float64_bytes():
    data = proto.step(7, 0.7, np.array([1.0, -2.0, 0.5]), np.array([1.5, 30.0]))
    (n,) = struct.unpack(">I", data[:4])
    msg = msgpack.unpackb(data[4:], raw=False)
    assert n == len(data) - 4
    assert msg["type"] == "step" and msg["seq"] == 7 and msg["t"] == 0.7
    assert msg["odom"] == [1.0, -2.0, 0.5]
    assert msg["ranges"] == struct.pack("<2d", 1.5, 30.0)


@pytest.mark.parametrize(
    ("payload", "needle"),
    [
        (b"\xc1", "not a msgpack message"),  # 0xc1 is never used in msgpack
        (msgpack.packb([1, 2]), "must be a map with a string 'type'"),
        (msgpack.packb({"kind": "estimate"}), "must be a map with a string 'type'"),
    ],
)
def test_garbage_is_a_protocol_error(payload, needle):
    with pytest.raises(proto.ProtocolError, match=needle):
        proto.unpack(payload)


def test_hello_checks_protocol_and_version():
    ok = {"type": "hello", "protocol": "mapqual-slam", "version": 1, "name": "x"}
    assert proto.check_hello(ok) == ("x", 1)
    assert proto.check_hello({**ok, "version": 2}) == ("x", 2)
    assert proto.hello()["versions"] == [1, 2]
    for bad in (3, 0, True, "2", None):
        with pytest.raises(
            proto.ProtocolError, match=f"speaks version {bad!r}; mapqual speaks 1 and 2"
        ):
            proto.check_hello({**ok, "version": bad})
    with pytest.raises(proto.ProtocolError, match="protocol 'ros'"):
        proto.check_hello({**ok, "protocol": "ros"})
    with pytest.raises(proto.ProtocolError, match="reported an error: no licence"):
        proto.check_hello({"type": "error", "message": "no licence"})


@pytest.mark.parametrize("bad", [[1, 2], [1, 2, float("nan")], [1, 2, "3"], "pose", [True, 0, 0]])
def test_a_pose_is_three_finite_numbers(bad):
    with pytest.raises(proto.ProtocolError, match="'pose' must be three finite numbers"):
        proto.pose3({"pose": bad}, "pose")


def _header(w, h, origin=(0.0, 0.0), res=0.5, encoding="float32"):
    return {
        "resolution": res,
        "origin": list(origin),
        "width": w,
        "height": h,
        "encoding": encoding,
    }


def test_a_whole_int8_map_reads_as_ros_percentages_with_unknown_cells():
    # ROS OccupancyGrid: row 0 is the bottom row; -1 unknown, 0 free, 100 occupied
    data = np.array([[0, 100, -1], [50, -1, 0]], dtype=np.int8).tobytes()
    grid = read_map({**_header(3, 2, (1.0, 2.0), encoding="int8"), "data": data}, None, 0.25)
    want = np.array([[0.0, 1.0, np.nan], [0.5, np.nan, 0.0]], dtype=np.float32)
    np.testing.assert_array_equal(grid.prob, want)
    assert grid.resolution == 0.5 and list(grid.origin) == [1.0, 2.0]
    assert grid.occupied.tolist() == [[False, True, False], [True, False, False]]


def test_patches_are_laid_over_the_previous_map_moved_into_a_grown_extent():
    prev = OccupancyGrid(np.array([[0.0, 1.0], [0.5, np.nan]]), 0.5, np.array([0.0, 0.0]))
    # the map grew by one cell to the left and one below: the old (0, 0) is now cell (1, 1)
    patch = {"col": 0, "row": 0, "width": 2, "height": 1}
    patch["data"] = np.array([0.25, 0.75], dtype="<f4").tobytes()
    grid = read_map({**_header(3, 3, (-0.5, -0.5)), "patches": [patch]}, prev, 0.25)
    nan = np.nan
    want = np.array([[0.25, 0.75, nan], [nan, 0.0, 1.0], [nan, 0.5, nan]], dtype=np.float32)
    np.testing.assert_array_equal(grid.prob, want)


@pytest.mark.parametrize(
    ("m", "needle"),
    [
        ({**_header(2, 2), "data": b"\x00" * 15}, "must be 16 bytes of float32, got 15"),
        ({**_header(2, 2), "data": np.full(4, 1.5, "<f4").tobytes()}, "probabilities in"),
        ({**_header(2, 2, encoding="rgb"), "data": b""}, "'encoding' must be one of"),
        ({**_header(2, 2)}, "needs 'data'"),
        ({**_header(2, 2), "resolution": 0}, "'resolution' must be positive"),
        (
            {**_header(2, 2), "patches": [{"col": 1, "row": 1, "width": 2, "height": 1}]},
            "map patch 0 .* leaves the 2 x 2 map",
        ),
        ({**_header(2, 2, (0.2, 0.0)), "patches": []}, "fraction of a cell"),
    ],
)
def test_bad_maps_are_protocol_errors(m, needle):
    prev = OccupancyGrid(np.zeros((2, 2)), 0.5, np.zeros(2))
    with pytest.raises(proto.ProtocolError, match=needle):
        read_map(m, prev, 0.25)
