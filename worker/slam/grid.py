"""OccupancyGrid: a SLAM map as hit/visit probabilities, exportable as map_server PGM + YAML."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

# map_saver's output levels and the thresholds it writes in the YAML
PGM_OCCUPIED = 0
PGM_FREE = 254
PGM_UNKNOWN = 205
YAML_OCCUPIED_THRESH = 0.65
YAML_FREE_THRESH = 0.196


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A 2D occupancy map.

    prob: (H, W) float32, indexed [iy, ix] with iy = 0 the bottom row; the share of laser
        beams through a cell that ended in it (GMapping's hits / visits), NaN = never seen.
    resolution: [m] cell side.
    origin: (2,) [m] world position of the lower-left corner of cell (0, 0).
    occ_thresh: a cell is occupied above this probability when published (GMapping's
        occ_thresh, 0.25), free at or below it.
    hits: None, or (H, W) float32 the number of beam end points in each cell (GMapping's
        hits, the ratio's numerator): where a noisy laser's end points are densest, which the
        ratio alone does not tell (the map score's "density" walls). Only the final map of a
        run carries it (the SLAMs' `occupancy_with_hits`); a map read from files has none.
    """

    prob: np.ndarray
    resolution: float
    origin: np.ndarray
    occ_thresh: float = 0.25
    hits: np.ndarray | None = None

    def __post_init__(self) -> None:
        prob = np.array(self.prob, dtype=np.float32, copy=True)
        if prob.ndim != 2:
            raise ValueError(f"prob must be 2D (H, W), got shape {prob.shape}")
        origin = np.array(self.origin, dtype=np.float64, copy=True).reshape(2)
        prob.setflags(write=False)
        origin.setflags(write=False)
        object.__setattr__(self, "prob", prob)
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "resolution", float(self.resolution))
        object.__setattr__(self, "hits", _hits_for(self.hits, prob.shape))

    @classmethod
    def adopt(
        cls, prob: np.ndarray, resolution: float, origin: np.ndarray, occ_thresh: float = 0.25
    ) -> OccupancyGrid:
        """A grid around `prob`, a (H, W) float32 array made for it that nobody else holds or
        writes: made read-only in place, not copied (the constructor copies)."""
        if prob.dtype != np.float32 or prob.ndim != 2 or not prob.flags.c_contiguous:
            return cls(prob, resolution, origin, occ_thresh)
        prob.setflags(write=False)
        origin = np.array(origin, dtype=np.float64, copy=True).reshape(2)
        origin.setflags(write=False)
        grid = object.__new__(cls)
        for name, value in (
            ("prob", prob), ("resolution", float(resolution)), ("origin", origin),
            ("occ_thresh", float(occ_thresh)), ("hits", None),
        ):  # fmt: skip
            object.__setattr__(grid, name, value)
        return grid

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) in cells."""
        return self.prob.shape  # type: ignore[return-value]

    @property
    def known(self) -> np.ndarray:
        """(H, W) bool: cells seen at least once."""
        return ~np.isnan(self.prob)

    @property
    def occupied(self) -> np.ndarray:
        """(H, W) bool: cells above occ_thresh (unknown cells are not occupied)."""
        with np.errstate(invalid="ignore"):
            return np.nan_to_num(self.prob, nan=0.0) > self.occ_thresh

    @property
    def free(self) -> np.ndarray:
        """(H, W) bool: seen cells at or below occ_thresh."""
        return self.known & ~self.occupied

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) [m] world points -> (N, 2) int64 [ix, iy] (may lie outside the grid)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        return np.floor((xy - self.origin) / self.resolution).astype(np.int64)

    def to_ros(self) -> np.ndarray:
        """(H, W) int8 as slam_gmapping publishes it: -1 unknown, 0 free, 100 occupied."""
        out = np.zeros(self.prob.shape, dtype=np.int8)
        out[self.occupied] = 100
        out[~self.known] = -1
        return out

    def to_image(self) -> np.ndarray:
        """(H, W) uint8 image, TOP row first, with map_saver's levels (0 / 254 / 205)."""
        return ros_to_image(self.to_ros())

    def save_map_server(self, stem: str | Path) -> tuple[Path, Path]:
        """Write `stem.pgm` and `stem.yaml` as ROS map_server's map_saver does; return both."""
        stem = Path(stem)
        pgm, yml = stem.with_suffix(".pgm"), stem.with_suffix(".yaml")
        data, text = map_server_files(self.to_ros(), self.resolution, self.origin, pgm.name)
        pgm.write_bytes(data)
        yml.write_text(text)
        return pgm, yml

    def save_png(self, path: str | Path) -> Path:
        """Write the map as a greyscale PNG (map_saver's levels), top row first."""
        from PIL import Image

        path = Path(path)
        Image.fromarray(self.to_image()).save(path)
        return path


def _hits_for(hits: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """`hits` as a read-only float32 copy of the grid's shape (None stays None)."""
    if hits is None:
        return None
    out = np.array(hits, dtype=np.float32, copy=True)
    if out.shape != shape:
        raise ValueError(f"hits must have the map's shape {shape}, got {out.shape}")
    out.setflags(write=False)
    return out


def map_server_files(
    grid_ros: np.ndarray, resolution: float, origin: np.ndarray, image_name: str = "map.pgm"
) -> tuple[bytes, str]:
    """(PGM bytes, YAML text) as ROS map_server's map_saver writes them, for a `(H, W) int8`
    ROS grid (bottom row first) of `resolution` [m] with its lower-left corner at `origin`
    (2,) [m]; the YAML names the image `image_name`. The one writer of map files."""
    img = ros_to_image(grid_ros)
    header = f"P5\n# CREATOR: mapqual {resolution:.3f} m/pix\n"
    header += f"{img.shape[1]} {img.shape[0]}\n255\n"
    yaml_text = (
        f"image: {image_name}\n"
        f"resolution: {resolution:.6f}\n"
        f"origin: [{origin[0]:.6f}, {origin[1]:.6f}, 0.000000]\n"
        "negate: 0\n"
        f"occupied_thresh: {YAML_OCCUPIED_THRESH}\n"
        f"free_thresh: {YAML_FREE_THRESH}\n\n"
    )
    return header.encode("ascii") + img.tobytes(), yaml_text


def ros_to_image(grid_ros: np.ndarray) -> np.ndarray:
    """`(H, W) int8` ROS occupancy (-1 unknown, 0..100), bottom row first, to the `(H, W) uint8`
    image map_saver writes, top row first."""
    img = np.full(grid_ros.shape, PGM_UNKNOWN, dtype=np.uint8)
    # map_saver: 0 <= v <= threshold_free (25) -> free; v >= threshold_occupied (65) -> occ
    img[(grid_ros >= 0) & (grid_ros <= 25)] = PGM_FREE
    img[grid_ros >= 65] = PGM_OCCUPIED
    return np.flipud(img)
