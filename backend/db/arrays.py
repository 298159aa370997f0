"""Compact storage of numpy arrays in a database column (zlib-compressed .npy bytes)."""

from __future__ import annotations

import io
import zlib

import numpy as np


def pack_array(arr: np.ndarray) -> bytes:
    """Serialise an array losslessly (dtype and shape kept) and compress it."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(arr), allow_pickle=False)
    return zlib.compress(buf.getvalue(), level=6)


def unpack_array(blob: bytes) -> np.ndarray:
    """Inverse of `pack_array`."""
    return np.load(io.BytesIO(zlib.decompress(blob)), allow_pickle=False)
