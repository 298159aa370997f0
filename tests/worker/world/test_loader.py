"""load_world: each input form (image + resolution, map_server YAML, Stage .world), each pixel
format, and each validation error."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from worker.errors import InputError
from worker.world import load_world


def plan_grey() -> np.ndarray:
    """A 100 x 60 px plan (image rows top first): wall 0, free 255, a grey 200 block (obstacle
    under the >= 250 rule), a 252 strip (free), a 3 x 3 black pillar near the top-left."""
    img = np.zeros((60, 100), dtype=np.uint8)
    img[2:-2, 2:-2] = 255
    img[40:50, 70:90] = 200  # grey: furniture
    img[10:12, 10:60] = 252  # light grey: free
    img[5:8, 5:8] = 0  # top-left pillar: image rows 5..7 -> grid rows 52..54
    return img


def save(img: np.ndarray, path, mode: str | None = None) -> None:
    im = Image.fromarray(img)
    if mode:
        im = im.convert(mode)
    im.save(path)


def expected_occ(img: np.ndarray) -> np.ndarray:
    return np.flipud(img < 250)


@pytest.mark.parametrize("mode", ["L", "RGB", "RGBA", "LA", "P"])
def test_image_plus_resolution_in_every_pixel_mode(tmp_path, mode):
    img = plan_grey()
    path = tmp_path / f"plan_{mode}.png"
    save(img, path, mode)
    world = load_world(path, 0.05)
    np.testing.assert_array_equal(world.occ, expected_occ(img))
    assert world.name == f"plan_{mode}"
    assert world.warnings == ()
    np.testing.assert_array_equal(world.origin, [0.0, 0.0])
    # The pillar at image rows 5..7 is near the TOP: grid rows 52..54 (bottom row first).
    assert world.occ[52:55, 5:8].all() and not world.occ[5:8, 5:8].any()


def test_pgm_and_bmp(tmp_path):
    img = plan_grey()
    for suffix in (".pgm", ".bmp"):
        path = tmp_path / f"plan{suffix}"
        save(img, path)
        np.testing.assert_array_equal(load_world(path, 0.1).occ, expected_occ(img))


def test_an_image_needs_a_resolution(tmp_path):
    path = tmp_path / "plan.png"
    save(plan_grey(), path)
    with pytest.raises(InputError, match="needs its resolution"):
        load_world(path)
    with pytest.raises(InputError, match="outside"):
        load_world(path, 2.0)


def test_map_server_yaml(tmp_path):
    img = plan_grey()
    save(img, tmp_path / "m.pgm")
    (tmp_path / "m.yaml").write_text(
        "image: m.pgm\nresolution: 0.05\norigin: [-2.0, 1.5, 0.0]\nnegate: 0\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    world = load_world(tmp_path / "m.yaml")
    # map_server: p = (255 - v) / 255 < 0.196 is free -> v > 205: 252 and 255 free, 200 not.
    np.testing.assert_array_equal(world.occ, np.flipud(img <= 205))
    np.testing.assert_array_equal(world.origin, [-2.0, 1.5])
    assert world.resolution == 0.05
    # --resolution overrides the YAML's.
    assert load_world(tmp_path / "m.yaml", 0.1).resolution == 0.1


def test_map_server_yaml_negate_and_thresholds(tmp_path):
    img = 255 - plan_grey()  # inverted image
    save(img, tmp_path / "n.png")
    (tmp_path / "n.yaml").write_text(
        "image: n.png\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 1\n"
        "occupied_thresh: 0.65\nfree_thresh: 0.02\n"
    )
    world = load_world(tmp_path / "n.yaml")
    np.testing.assert_array_equal(world.occ, expected_occ(plan_grey()))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("image: [unclosed\n", "not valid YAML"),
        ("resolution: 0.05\n", "no `image:` key"),
        ("image: m.png\n", "no `resolution:`"),
        ("image: m.png\nresolution: 0.05\norigin: [a, b, c]\n", "must be numbers"),
        ("image: missing.png\nresolution: 0.05\n", "no such file"),
        ("image: m.png\nresolution: 0.05\nfree_thresh: 0.9\n", "free_thresh"),
    ],
)
def test_yaml_errors(tmp_path, text, message):
    save(plan_grey(), tmp_path / "m.png")
    (tmp_path / "bad.yaml").write_text(text)
    with pytest.raises(InputError, match=message):
        load_world(tmp_path / "bad.yaml")


def test_stage_world_file(tmp_path):
    img = plan_grey()  # 100 x 60 px
    save(img, tmp_path / "cave.png")
    (tmp_path / "cave.world").write_text(
        "# a Stage world\n"
        'include "pioneer.inc"\n'
        'define floorplan model ( color "gray30" boundary 1 )\n'
        "resolution 0.02\n"
        "window ( size [ 635 666 ] scale 37 )\n"
        'floorplan ( name "cave" bitmap "cave.png" size [10.0 6.0 0.8] pose [1 2 0 0] )\n'
        'pioneer2dx ( name "r0" pose [ -1.0 0.5 0 90 ] sicklaser( pose [0 0 0 0] ) )\n'
    )
    world = load_world(tmp_path / "cave.world")
    assert world.resolution == pytest.approx(0.1)
    # The bitmap is centred on the floorplan's pose: lower-left = (1 - 5, 2 - 3).
    np.testing.assert_allclose(world.origin, [-4.0, -1.0])
    np.testing.assert_allclose(world.start_pose, [-1.0, 0.5, math.pi / 2])
    np.testing.assert_array_equal(world.occ, expected_occ(img))


@pytest.mark.parametrize("yaw", [90, -90, 180])
def test_stage_world_rotated_bitmap(tmp_path, yaw):
    img = np.full((40, 80), 255, dtype=np.uint8)  # 8 m x 4 m at 0.1 m/px
    img[0, :] = img[-1, :] = img[:, 0] = img[:, -1] = 0
    img[1:5, 1:5] = 0  # a block in the image's top-left corner
    save(img, tmp_path / "r.png")
    (tmp_path / "r.world").write_text(
        f'model ( bitmap "r.png" size [8 4 1] pose [10 20 {yaw}] )\n'  # Stage 3: [x y yaw]
    )
    world = load_world(tmp_path / "r.world")
    quarter = yaw % 360 // 90
    width, height = (8.0, 4.0) if quarter % 2 == 0 else (4.0, 8.0)
    assert (world.width_m, world.height_m) == pytest.approx((width, height))
    np.testing.assert_allclose(world.origin, [10 - width / 2, 20 - height / 2])
    # Unrotated, the block is at the top-left; turning the map by +90 degrees (CCW) moves the
    # top-left corner to the bottom-left, by 180 to the bottom-right, by -90 to the top-right.
    corner = {1: (10 - 1.8, 20 - 3.8), 2: (10 + 3.8, 20 - 1.8), 3: (10 + 1.8, 20 + 3.8)}[quarter]
    assert not world.is_free(*corner)
    far = {1: (10 + 1.5, 20 + 3.5), 2: (10 - 3.5, 20 + 1.5), 3: (10 - 1.5, 20 - 3.5)}[quarter]
    assert world.is_free(*far)


def test_stage_world_errors(tmp_path):
    save(plan_grey(), tmp_path / "cave.png")
    path = tmp_path / "bad.world"
    path.write_text('floorplan ( bitmap "cave.png" )\n')
    with pytest.raises(InputError, match="no `size"):
        load_world(path)
    path.write_text('floorplan ( bitmap "cave.png" size [10 2 1] )\n')
    with pytest.raises(InputError, match="non-square pixels"):
        load_world(path)
    path.write_text('floorplan ( bitmap "cave.png" size [10 6 1]\n')
    with pytest.raises(InputError, match="never closed"):
        load_world(path)
    path.write_text('floorplan ( bitmap "cave.png" size [10 6 1] pose [0 0 0 45] )\n')
    with pytest.raises(InputError, match="multiples of 90"):
        load_world(path)
    path.write_text("window ( size [1 1] )\n")
    with pytest.raises(InputError, match="no floorplan"):
        load_world(path)


def test_unreadable_and_oversized_images(tmp_path):
    bogus = tmp_path / "fake.png"
    bogus.write_text("this is not a png")
    with pytest.raises(InputError, match="not a readable image"):
        load_world(bogus, 0.05)
    path = tmp_path / "plan.png"
    save(plan_grey(), path)
    with pytest.raises(InputError, match="more than the limit of 5,000"):
        load_world(path, 0.05, max_pixels=5000)
    with pytest.raises(InputError, match="no such file"):
        load_world(tmp_path / "nope.png", 0.05)
    with pytest.raises(InputError, match="folder"):
        load_world(tmp_path, 0.05)


def test_transparent_pixels_are_obstacles(tmp_path):
    rgba = np.dstack([plan_grey()] * 3 + [np.full((60, 100), 255, np.uint8)])
    rgba[30:35, 30:35, 3] = 0
    path = tmp_path / "alpha.png"
    Image.fromarray(rgba, "RGBA").save(path)
    world = load_world(path, 0.05)
    assert world.occ[60 - 35 : 60 - 30, 30:35].all()
    assert any("transparent" in w for w in world.warnings)


def test_segmentation_room_count(tmp_path):
    img = plan_grey()
    save(img, tmp_path / "plan.png")
    seg = np.zeros((60, 100), dtype=np.uint8)
    seg[2:-2, 2:46] = 255  # room 1: 44 x 56 px at 0.05 m -> 6.2 m^2
    seg[2:-2, 50:-2] = 255  # room 2, apart from room 1 by a 4 px line
    seg[3:5, 48:49] = 255  # a speck (below 1 m^2) between them is not a room
    save(seg, tmp_path / "seg.png")
    world = load_world(tmp_path / "plan.png", 0.05, segmentation=tmp_path / "seg.png")
    assert world.facts.n_rooms == 2
    save(seg[:50], tmp_path / "small.png")
    with pytest.raises(InputError, match="segmentation image is 100 x 50"):
        load_world(tmp_path / "plan.png", 0.05, segmentation=tmp_path / "small.png")


def test_a_decompression_bomb_is_refused_from_its_header(tmp_path):
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (
            struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
        )

    def bomb(width: int, height: int) -> bytes:
        header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
        return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IEND", b"")

    # Tiny files claiming huge images are refused before any pixel is decoded: above our
    # 64 Mpx limit by us, far above it by Pillow's own guard.
    path = tmp_path / "bomb.png"
    path.write_bytes(bomb(10000, 8000))
    with pytest.raises(InputError, match="10000 x 8000 = 80,000,000 pixels, more than the limit"):
        load_world(path, 0.05)
    path.write_bytes(bomb(20000, 20000))
    with pytest.raises(InputError, match="image too large: .*400000000 pixels"):
        load_world(path, 0.05)


def test_map_server_modes_other_than_trinary_are_reported(tmp_path):
    save(plan_grey(), tmp_path / "m.png")
    (tmp_path / "m.yaml").write_text("image: m.png\nresolution: 0.05\nmode: scale\n")
    world = load_world(tmp_path / "m.yaml")
    assert any("mode 'scale'" in w for w in world.warnings)
    np.testing.assert_array_equal(world.occ, np.flipud(plan_grey() <= 205))
