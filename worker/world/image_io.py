"""Read a floorplan image (PNG/PGM/BMP; grey, RGB, RGBA, palette) into grey levels and alpha."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from worker.errors import InputError

MAX_PIXELS = 64_000_000  # default limit on width * height (also guards against decompression bombs)


class ImageTooLarge(InputError):
    """An image whose header declares more pixels than allowed (the API answers 413)."""


def image_size(path: Path, max_pixels: int = MAX_PIXELS) -> tuple[int, int]:
    """`(width, height)` from the image's header, no pixel decoded; ImageTooLarge past
    `max_pixels`, InputError if it is no readable image."""
    with _opened(path, max_pixels) as im:
        return im.size


def read_grey(path: Path, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray, np.ndarray | None]:
    """Grey levels `(H, W)` uint8 (top image row FIRST) and alpha `(H, W)` uint8 or None.

    Colour is averaged over the channels (rounded down, as map_server does). Alpha is returned
    only when some pixel is not fully opaque. The size is checked from the header before
    decoding, and nothing wider than a byte per pixel is made (25 MP stay 25 MB).
    """
    with _opened(path, max_pixels) as im:
        try:
            im.load()
            return _to_grey(im, path)
        except InputError:
            raise
        except (OSError, SyntaxError, ValueError) as exc:
            raise InputError(f"not a readable image: {exc}", path=path) from None


class _opened:
    """`with _opened(path, max_pixels) as im`: a lazily opened image whose declared size is
    within the limit; every failure to open it is an InputError."""

    def __init__(self, path: Path, max_pixels: int):
        self.path, self.max_pixels, self.im = path, max_pixels, None

    def __enter__(self) -> Image.Image:
        path = self.path
        if not path.is_file():
            raise InputError("no such file", path=path)
        try:
            with warnings.catch_warnings():
                # The size is checked below against our own limit before any pixel is decoded.
                warnings.simplefilter("ignore", Image.DecompressionBombWarning)
                self.im = Image.open(path)
        except Image.DecompressionBombError as exc:
            # Pillow refuses images beyond twice its own limit before we see their size.
            raise ImageTooLarge(
                f"image too large: {exc} (the limit is {self.max_pixels:,} pixels)", path=path
            ) from None
        except UnidentifiedImageError as exc:
            raise InputError(
                f"not a readable image ({exc.__class__.__name__})", path=path
            ) from None
        except (OSError, SyntaxError, ValueError) as exc:
            raise InputError(f"not a readable image: {exc}", path=path) from None
        width, height = self.im.size
        if width * height > self.max_pixels:
            self.im.close()
            raise ImageTooLarge(
                f"image is {width} x {height} = {width * height:,} pixels, more than the "
                f"limit of {self.max_pixels:,}",
                path=path,
            )
        return self.im

    def __exit__(self, *exc: object) -> None:
        if self.im is not None:
            self.im.close()


def _to_grey(im: Image.Image, path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Convert a decoded PIL image to (grey, alpha-or-None), both uint8."""
    mode = im.mode
    if mode == "P":
        im = im.convert("RGBA" if "transparency" in im.info else "RGB")
        mode = im.mode
    if mode in ("1", "L"):
        return np.asarray(im.convert("L"), dtype=np.uint8), None
    if mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        return _wide_to_uint8(np.asarray(im)), None
    if mode in ("LA", "La", "PA"):
        arr = np.asarray(im.convert("LA"), dtype=np.uint8)
        return arr[..., 0].copy(), _alpha_or_none(arr[..., 1])
    if mode in ("RGB", "RGBA", "RGBX", "RGBa", "CMYK", "YCbCr", "HSV", "LAB"):
        has_alpha = mode in ("RGBA", "RGBa")
        arr = np.asarray(im.convert("RGBA" if has_alpha else "RGB"), dtype=np.uint8)
        total = arr[..., 0].astype(np.uint16)
        total += arr[..., 1]
        total += arr[..., 2]
        # floor of the mean, as map_server's integer average: grey >= k iff sum >= 3k
        grey = (total // 3).astype(np.uint8)
        return grey, _alpha_or_none(arr[..., 3]) if has_alpha else None
    raise InputError(f"unsupported image mode {mode!r}", path=path)


def _wide_to_uint8(arr: np.ndarray) -> np.ndarray:
    """16-bit or 32-bit grey to 0..255: values up to 255 are kept, larger ones scaled from
    0..65535 and rounded down (so `grey >= 250` holds exactly where the scaled value does)."""
    if arr.dtype.kind == "f":
        arr = np.clip(np.nan_to_num(arr), 0, 65535).astype(np.uint32)
    arr = np.clip(arr, 0, 65535).astype(np.uint32, copy=False)
    if arr.size and int(arr.max()) > 255:
        return ((arr * 255) // 65535).astype(np.uint8)
    return arr.astype(np.uint8)


def _alpha_or_none(alpha: np.ndarray) -> np.ndarray | None:
    """Alpha when some pixel is not opaque, else None (opaque alpha is ignored)."""
    return None if bool((alpha >= 255).all()) else alpha.copy()
