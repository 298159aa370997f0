"""Room counts from a segmentation image (Bormann `gt_segmentation`: lines across doorways)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy import ndimage

from worker.errors import InputError
from worker.world.image_io import read_grey

MIN_ROOM_M2 = 1.0  # [m^2] white patches smaller than this are specks, not rooms
_FOUR = ndimage.generate_binary_structure(2, 1)


def count_rooms(
    path: Path,
    resolution: float,
    shape: tuple[int, int],
    max_pixels: int,
    min_room_m2: float = MIN_ROOM_M2,
) -> int:
    """Flood fill the white (grey >= 250) of the image; count regions of at least `min_room_m2`.

    The image must have the floorplan's `shape` `(H, W)`; the doorway lines split the rooms.
    """
    grey, _ = read_grey(path, max_pixels)
    if grey.shape != tuple(shape):
        raise InputError(
            f"segmentation image is {grey.shape[1]} x {grey.shape[0]} pixels, the floorplan "
            f"{shape[1]} x {shape[0]}",
            path=path,
        )
    labels, n = ndimage.label(grey >= 250, structure=_FOUR)
    if n == 0:
        return 0
    sizes = np.bincount(labels.ravel())[1:]
    return int((sizes * resolution * resolution >= min_room_m2).sum())
