"""OccupancyGrid: ROS values, map_server PGM + YAML as map_saver writes them, PNG."""

from __future__ import annotations

import numpy as np
import yaml
from PIL import Image

from worker.slam.grid import OccupancyGrid, map_server_files


def _grid() -> OccupancyGrid:
    # 2 rows x 3 cols, bottom row first: row 0 = [unknown, 0.0, 0.9], row 1 = [0.25, 0.3, 1.0]
    prob = np.array([[np.nan, 0.0, 0.9], [0.25, 0.3, 1.0]], dtype=np.float32)
    return OccupancyGrid(prob, 0.05, np.array([-1.0, 2.5]))


def test_to_ros_is_trinary_with_gmapping_occ_thresh():
    ros = _grid().to_ros()
    assert ros.dtype == np.int8
    # 0.25 is not above occ_thresh 0.25 -> free; 0.3 above -> occupied
    assert ros.tolist() == [[-1, 0, 100], [0, 100, 100]]


def test_map_server_files(tmp_path):
    pgm, yml = _grid().save_map_server(tmp_path / "map")
    data = pgm.read_bytes()
    assert data.startswith(b"P5\n")
    # header: magic, comment, "W H", maxval; then the rows, TOP row (our row 1) first
    lines = data.split(b"\n", 4)
    assert lines[2] == b"3 2" and lines[3] == b"255"
    assert list(lines[4]) == [254, 0, 0, 205, 254, 0]
    meta = yaml.safe_load(yml.read_text())
    assert meta["image"] == "map.pgm"
    assert meta["resolution"] == 0.05
    assert meta["origin"] == [-1.0, 2.5, 0.0]
    assert meta["negate"] == 0
    assert meta["occupied_thresh"] == 0.65 and meta["free_thresh"] == 0.196
    # PIL reads the PGM back as the same image
    assert np.array(Image.open(pgm)).tolist() == [[254, 0, 0], [205, 254, 0]]


def test_png_matches_pgm(tmp_path):
    g = _grid()
    path = g.save_png(tmp_path / "map.png")
    assert np.array(Image.open(path)).tolist() == [[254, 0, 0], [205, 254, 0]]


def test_world_to_cell_and_readonly():
    g = _grid()
    cells = g.world_to_cell(np.array([[-1.0, 2.5], [-0.951, 2.549], [-1.001, 2.6]]))
    assert cells.tolist() == [[0, 0], [0, 0], [-1, 2]]
    assert not g.prob.flags.writeable and not g.origin.flags.writeable
    assert g.known.sum() == 5 and g.occupied.sum() == 3 and g.free.sum() == 2


def test_the_one_map_writer_is_byte_exact():
    # map_saver's layout at the precision every report folder has had (hand-written)
    pgm, text = map_server_files(_grid().to_ros(), 0.05, np.array([-1.0, 2.5]), "m.pgm")
    header = b"P5\n# CREATOR: mapqual 0.050 m/pix\n3 2\n255\n"
    assert pgm == header + bytes([254, 0, 0, 205, 254, 0])
    assert text == (
        "image: m.pgm\nresolution: 0.050000\norigin: [-1.000000, 2.500000, 0.000000]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n\n"
    )
