"""Read a floorplan image (PNG/PGM/BMP; grey, RGB, RGBA, palette) into grey levels and alpha."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from worker.errors import InputError

MAX_PIXELS = 64_000_000  # default limit on width * height (also guards against decompression bombs)


def read_grey(path: Path, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray, np.ndarray | None]:
    """Grey levels `(H, W)` float64 in 0..255 (top image row FIRST) and alpha `(H, W)` or None.

    Colour is averaged over the channels, as map_server does. Alpha is returned only when some
    pixel is not fully opaque. The size is checked from the header before decoding.
    """
    if not path.is_file():
        raise InputError("no such file", path=path)
    try:
        with warnings.catch_warnings():
            # The size is checked below against our own limit before any pixel is decoded.
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                width, height = im.size
                if width * height > max_pixels:
                    raise InputError(
                        f"image is {width} x {height} = {width * height:,} pixels, more than the "
                        f"limit of {max_pixels:,}",
                        path=path,
                    )
                im.load()
                return _to_grey(im, path)
    except Image.DecompressionBombError as exc:
        # Pillow refuses images beyond twice its own limit before we see their size.
        raise InputError(f"image too large: {exc}", path=path) from None
    except UnidentifiedImageError as exc:
        raise InputError(f"not a readable image ({exc.__class__.__name__})", path=path) from None
    except (OSError, SyntaxError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"not a readable image: {exc}", path=path) from None


def _to_grey(im: Image.Image, path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Convert a decoded PIL image to (grey, alpha-or-None)."""
    mode = im.mode
    if mode == "P":
        im = im.convert("RGBA" if "transparency" in im.info else "RGB")
        mode = im.mode
    if mode in ("1", "L"):
        return np.asarray(im.convert("L"), dtype=np.float64), None
    if mode in ("I;16", "I;16B", "I;16L", "I", "F"):
        arr = np.asarray(im, dtype=np.float64)
        top = 65535.0 if arr.max() > 255 else 255.0
        return arr * (255.0 / top), None
    if mode in ("LA", "La", "PA"):
        im = im.convert("LA")
        arr = np.asarray(im, dtype=np.float64)
        return arr[..., 0], _alpha_or_none(arr[..., 1])
    if mode in ("RGB", "RGBA", "RGBX", "RGBa", "CMYK", "YCbCr", "HSV", "LAB"):
        has_alpha = mode in ("RGBA", "RGBa")
        arr = np.asarray(im.convert("RGBA" if has_alpha else "RGB"), dtype=np.float64)
        grey = arr[..., :3].mean(axis=2)
        return grey, _alpha_or_none(arr[..., 3]) if has_alpha else None
    raise InputError(f"unsupported image mode {mode!r}", path=path)


def _alpha_or_none(alpha: np.ndarray) -> np.ndarray | None:
    """Alpha when some pixel is not opaque, else None (opaque alpha is ignored)."""
    return None if bool((alpha >= 255).all()) else alpha
