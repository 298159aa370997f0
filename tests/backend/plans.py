"""Small floorplans for the backend's tests that run the real pipeline."""

from __future__ import annotations

import numpy as np


def rooms_occupancy(nx: int, ny: int, room_px: int = 120) -> np.ndarray:
    """(H, W) bool: nx x ny rooms of room_px pixels (6 m at 0.05 m/px) with 1 m doors."""
    occ = np.zeros((ny * room_px + 1, nx * room_px + 1), bool)
    occ[:, ::room_px] = True
    occ[::room_px, :] = True
    for i in range(1, nx):
        occ[50:-50, i * room_px] = np.arange(ny * room_px - 99) % room_px >= 20
    for j in range(1, ny):
        occ[j * room_px, 50:-50] = np.arange(nx * room_px - 99) % room_px >= 20
    return occ
