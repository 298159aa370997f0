"""The pixel cap is judged from the header, before any decoding, in every format the loader
reads; decoded images are uint8, never float64."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest
from PIL import Image

from worker.errors import InputError
from worker.world.image_io import ImageTooLarge, image_size, read_grey

LIMIT = 25_000_000


def _pgm(w: int, h: int) -> bytes:
    return b"P5\n%d %d\n255\n" % (w, h) + b"\xff" * 64


def _bmp(w: int, h: int) -> bytes:
    info = struct.pack("<IiiHHIIiiII", 40, w, h, 1, 8, 0, 0, 2835, 2835, 0, 0)
    return (
        b"BM"
        + struct.pack("<IHHI", 14 + 40 + 1024 + 64, 0, 0, 14 + 40 + 1024)
        + info
        + (b"\0" * 1088)
    )


def _gif(w: int, h: int) -> bytes:
    return (
        b"GIF89a"
        + struct.pack("<HHBBB", w, h, 0, 0, 0)
        + b",\0\0\0\0"
        + (struct.pack("<HH", w, h) + b"\0\x02\x02D\x01\0;")
    )


@pytest.mark.parametrize("fmt", ["pgm", "bmp", "gif"])
@pytest.mark.parametrize(("w", "h"), [(6000, 6000), (60000, 60000)])
def test_too_many_pixels_are_refused_from_the_header_alone(tmp_path, fmt, w, h):
    path = tmp_path / f"big.{fmt}"
    path.write_bytes({"pgm": _pgm, "bmp": _bmp, "gif": _gif}[fmt](w, h))
    t0 = time.monotonic()
    with pytest.raises(ImageTooLarge) as err:
        image_size(path, LIMIT)
    with pytest.raises(ImageTooLarge):
        read_grey(path, LIMIT)
    assert time.monotonic() - t0 < 0.5
    assert "25,000,000" in str(err.value) and "\n" not in str(err.value)


def test_a_small_header_is_read_and_decoded_to_uint8(tmp_path):
    img = np.zeros((30, 40, 3), np.uint8)
    img[..., 0], img[..., 1], img[..., 2] = 250, 251, 250  # mean 250.33: free (>= 250)
    img[0, 0] = (249, 250, 250)  # mean 249.67: not free, as map_server's integer mean
    path = tmp_path / "rgb.png"
    Image.fromarray(img).save(path)
    assert image_size(path, LIMIT) == (40, 30)
    grey, alpha = read_grey(path, LIMIT)
    assert grey.dtype == np.uint8 and alpha is None
    assert grey[0, 0] == 249 and (grey >= 250).sum() == 30 * 40 - 1
    with pytest.raises(InputError, match="not a readable image"):
        (tmp_path / "x.png").write_bytes(b"\x89PNG\r\n\x1a\nnonsense")
        image_size(tmp_path / "x.png", LIMIT)
