"""The World: an occupancy grid in the map_server frame, its start pose and its facts."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from worker.errors import InputError
from worker.robot import FOOTPRINT_M
from worker.world import analysis

RESOLUTION_MIN = 0.005  # [m/cell] exclusive
RESOLUTION_MAX = 1.0  # [m/cell] inclusive


@dataclass(frozen=True)
class WorldFacts:
    """Summary numbers of a floorplan (all JSON-serialisable)."""

    width_px: int
    height_px: int
    width_m: float  # [m]
    height_m: float  # [m]
    resolution: float  # [m/cell]
    free_area_m2: float  # [m^2] all free cells
    free_fraction: float  # free cells / all cells
    n_free_regions: int  # 4-connected free regions
    # The main region: the largest free region not touching the image border (else the
    # largest); the automatic start pose lies in it.
    largest_region_area_m2: float  # [m^2]
    largest_region_share: float  # its share of the free area
    main_region_enclosed: bool  # the main region does not touch the image border
    border_free: bool  # some free cell touches the image border (the border counts as a wall)
    clearance_mean_m: float  # [m] over the main region's cells
    clearance_median_m: float  # [m]
    clearance_p90_m: float  # [m] 90th percentile
    clearance_max_m: float  # [m]
    n_rooms: int | None  # rooms from a segmentation image, when one was given


@dataclass(frozen=True, eq=False)
class World:
    """A floorplan as an occupancy grid.

    `occ` is `(H, W)` bool, True = obstacle, indexed `[iy, ix]` with iy = 0 the BOTTOM row;
    cell (ix, iy) covers x in [ox + ix*res, ox + (ix+1)*res), y likewise. Outside the grid
    counts as a wall. `start_pose` is `(3,)` [x, y, theta] in the world frame.
    """

    name: str
    occ: np.ndarray
    resolution: float  # [m/cell]
    origin: np.ndarray  # (2,) [m] world position of the grid's lower-left corner
    start_pose: np.ndarray  # (3,) [x, y, theta]
    facts: WorldFacts
    warnings: tuple[str, ...] = ()
    source: str | None = None  # the file it was loaded from, if any
    clearance: np.ndarray = field(repr=False, default=None)  # (H, W) [m], see analysis

    @property
    def width_m(self) -> float:
        """Width of the grid [m]."""
        return self.occ.shape[1] * self.resolution

    @property
    def height_m(self) -> float:
        """Height of the grid [m]."""
        return self.occ.shape[0] * self.resolution

    @property
    def shape(self) -> tuple[int, int]:
        """Grid shape `(H, W)` in cells."""
        return self.occ.shape

    def world_to_cell(self, x: float, y: float) -> tuple[int, int]:
        """Cell `(ix, iy)` containing world point (x, y) [m] (may be outside the grid)."""
        return (
            math.floor((x - self.origin[0]) / self.resolution),
            math.floor((y - self.origin[1]) / self.resolution),
        )

    def is_free(self, x: float, y: float) -> bool:
        """Whether world point (x, y) lies in a free cell of the grid."""
        ix, iy = self.world_to_cell(x, y)
        h, w = self.occ.shape
        return 0 <= ix < w and 0 <= iy < h and not self.occ[iy, ix]

    def fingerprint(self) -> str:
        """A content hash: grid, resolution, origin and start pose (not the name), so that the
        same floorplan uploaded or loaded twice is recognised as one world."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.occ, dtype=bool).tobytes())
        h.update(repr((self.occ.shape, float(self.resolution))).encode())
        h.update(np.asarray(self.origin, dtype=np.float64).tobytes())
        h.update(np.asarray(self.start_pose, dtype=np.float64).tobytes())
        return h.hexdigest()

    @classmethod
    def from_array(
        cls,
        occ: np.ndarray,
        resolution: float,
        origin: tuple[float, float] | np.ndarray = (0.0, 0.0),
        start_pose: tuple[float, float, float] | np.ndarray | None = None,
        name: str = "array",
        *,
        footprint_m: float = FOOTPRINT_M,
        n_rooms: int | None = None,
        warnings: tuple[str, ...] = (),
        source: str | None = None,
    ) -> World:
        """Build and validate a World from a bool grid `(H, W)` (True = obstacle, bottom row first).

        Raises InputError when the resolution is out of range, there is no free space wide
        enough for the robot's footprint, or a given start pose is not on a free cell.
        """
        occ, resolution, origin_arr = _checked_grid(occ, resolution, origin)
        notes = list(warnings)
        clearance = analysis.clearance_map(occ, resolution)
        labels, n_regions = analysis.free_regions(occ)
        region, enclosed = analysis.main_region(labels, n_regions)
        _check_room_for_robot(name, clearance, labels, region, footprint_m)
        if _border_free(occ):
            notes.append("free space touches the image border; the border counts as a wall")
        if not enclosed:
            notes.append("no enclosed free region; the robot starts in one touching the border")
        if start_pose is None:
            pose = analysis.choose_start_pose(clearance, labels, region, resolution, origin_arr)
        else:
            pose = _checked_start_pose(start_pose, occ, resolution, origin_arr, name)
        in_region = labels == region
        facts = _world_facts(occ, resolution, n_regions, in_region, enclosed, clearance, n_rooms)
        occ.setflags(write=False)
        clearance.setflags(write=False)
        return cls(
            name=name,
            occ=occ,
            resolution=resolution,
            origin=origin_arr,
            start_pose=pose,
            facts=facts,
            warnings=tuple(notes),
            source=source,
            clearance=clearance,
        )


def _checked_grid(
    occ: np.ndarray, resolution: float, origin: tuple[float, float] | np.ndarray
) -> tuple[np.ndarray, float, np.ndarray]:
    """(occ (H, W) contiguous bool, resolution [m/cell], origin (2,) [m]) once checked."""
    occ = np.ascontiguousarray(np.asarray(occ, dtype=bool))
    if occ.ndim != 2 or occ.size == 0:
        raise InputError(f"occupancy grid must be a non-empty 2D array, got shape {occ.shape}")
    resolution = float(resolution)
    if not (RESOLUTION_MIN < resolution <= RESOLUTION_MAX):
        raise InputError(
            f"resolution {resolution:g} m/pixel is outside ({RESOLUTION_MIN:g}, "
            f"{RESOLUTION_MAX:g}] m"
        )
    origin_arr = np.asarray(origin, dtype=np.float64).reshape(-1)
    if origin_arr.shape != (2,) or not np.all(np.isfinite(origin_arr)):
        raise InputError(f"origin must be two finite numbers [x, y], got {origin!r}")
    return occ, resolution, origin_arr


def _check_room_for_robot(
    name: str, clearance: np.ndarray, labels: np.ndarray, region: int, footprint_m: float
) -> None:
    """InputError unless the main free region (label `region`) is wide enough for the robot."""
    if region == 0:
        raise InputError(f"{name}: the floorplan has no free cell")
    radius = analysis.footprint_radius(footprint_m)
    widest = float(clearance[labels == region].max())
    if widest < radius:
        raise InputError(
            f"{name}: no free space wide enough for the {footprint_m:.2f} m robot footprint "
            f"(largest clearance {widest:.2f} m, needs {radius:.2f} m); "
            "is the resolution right?"
        )


def _border_free(occ: np.ndarray) -> bool:
    """Whether some free cell lies on the grid's outer ring."""
    return bool(
        (~occ[0, :]).any() or (~occ[-1, :]).any() or (~occ[:, 0]).any() or (~occ[:, -1]).any()
    )


def _world_facts(
    occ: np.ndarray,
    resolution: float,
    n_regions: int,
    in_region: np.ndarray,
    enclosed: bool,
    clearance: np.ndarray,
    n_rooms: int | None,
) -> WorldFacts:
    """The summary numbers; `in_region` `(H, W)` bool marks the main free region."""
    cell_area = resolution * resolution
    free_cells = int((~occ).sum())
    region_cells = int(in_region.sum())
    region_clearance = clearance[in_region]
    return WorldFacts(
        width_px=int(occ.shape[1]),
        height_px=int(occ.shape[0]),
        width_m=occ.shape[1] * resolution,
        height_m=occ.shape[0] * resolution,
        resolution=resolution,
        free_area_m2=free_cells * cell_area,
        free_fraction=free_cells / occ.size,
        n_free_regions=n_regions,
        largest_region_area_m2=region_cells * cell_area,
        largest_region_share=region_cells / free_cells,
        main_region_enclosed=enclosed,
        border_free=_border_free(occ),
        clearance_mean_m=float(region_clearance.mean()),
        clearance_median_m=float(np.median(region_clearance)),
        clearance_p90_m=float(np.percentile(region_clearance, 90)),
        clearance_max_m=float(region_clearance.max()),
        n_rooms=n_rooms,
    )


def _checked_start_pose(
    start_pose, occ: np.ndarray, resolution: float, origin: np.ndarray, name: str
) -> np.ndarray:
    """Validate a given start pose `(3,)`: finite, on a free cell; theta wrapped to [-pi, pi)."""
    pose = np.asarray(start_pose, dtype=np.float64).reshape(-1)
    if pose.shape != (3,) or not np.all(np.isfinite(pose)):
        raise InputError(f"{name}: start pose must be three finite numbers [x, y, theta]")
    ix = math.floor((pose[0] - origin[0]) / resolution)
    iy = math.floor((pose[1] - origin[1]) / resolution)
    h, w = occ.shape
    if not (0 <= ix < w and 0 <= iy < h) or occ[iy, ix]:
        raise InputError(
            f"{name}: start pose ({pose[0]:.3f}, {pose[1]:.3f}) is not on a free cell of the map"
        )
    pose[2] = (pose[2] + math.pi) % (2.0 * math.pi) - math.pi
    return pose
