"""A floorplan's occupancy grid as a PNG, optionally shrunk to a thumbnail that keeps its walls."""

from __future__ import annotations

import io

import numpy as np


def shrink_occupancy(occ: np.ndarray, max_px: int) -> np.ndarray:
    """occ (H, W) bool reduced by a whole factor until both sides are <= max_px; a block is an
    obstacle when any of its cells is (one-cell walls survive, as they would not a resize)."""
    f = -(-max(occ.shape) // max_px)
    if f <= 1:
        return occ
    h, w = -(-occ.shape[0] // f) * f, -(-occ.shape[1] // f) * f
    padded = np.zeros((h, w), dtype=bool)
    padded[: occ.shape[0], : occ.shape[1]] = occ
    return padded.reshape(h // f, f, w // f, f).any(axis=(1, 3))


def occupancy_png(occ: np.ndarray, max_px: int | None = None) -> bytes:
    """occ (H, W) bool, bottom row first, as a PNG the right way up: obstacles black, free
    white; with max_px, no side longer than it (see shrink_occupancy)."""
    from PIL import Image

    if max_px is not None:
        occ = shrink_occupancy(occ, max_px)
    img = Image.fromarray(np.where(np.flipud(occ), 0, 255).astype(np.uint8), mode="L")
    buf = io.BytesIO()
    img.save(buf, format="PNG", optimize=True)
    return buf.getvalue()
