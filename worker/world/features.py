"""Floorplan features that predict map quality (issue 22): geometry, rooms, the medial-axis
graph, clearance, openness, scan-matching traps and clutter; pure functions on a World."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from worker.errors import InputError
from worker.world import features_kernels as fk
from worker.world.world import World


@dataclass(frozen=True)
class FeatureParams:
    """Settings of the feature extraction (the laser's as in SimParams)."""

    work_res_m: float = 0.1  # [m] the room/graph/openness grid is at least this coarse
    work_cells: int = 500  # [cells] and at most this many cells a side
    door_half_width_m: float = 0.45  # [m] clearance peaks under this are not rooms
    room_peak_m: float = 0.4  # [m] a room's clearance peak rises this far above its doors
    min_room_m2: float = 1.0  # [m^2] smaller cores are specks, not rooms
    corridor_elongation: float = 3.0  # [-] a room this elongated (length / width) is a corridor
    laser_range_m: float = 30.0  # [m] openness is what a laser of this range sees
    openness_samples: int = 64  # points the openness is averaged over
    openness_rays: int = 360  # rays per point (full circle)
    repeat_tolerance: float = 0.1  # [-] rooms within 10 % in area and axes are repeats
    min_loop_m2: float = 0.25  # [m^2] obstacles smaller than this do not make a loop
    seed: int = 0  # sample points are drawn with this seed: features are deterministic


@dataclass(frozen=True)
class WorldFeatures:
    """What the floorplan looks like to a mapping robot; units in the comments."""

    free_area_m2: float  # [m^2] the main free region (where the robot drives)
    perimeter_m: float  # [m] length of the region's boundary (free/obstacle cell edges)
    perimeter_per_area: float  # [1/m] perimeter / free area: wall per square metre
    n_rooms: int  # rooms (the world's segmentation where it has one, else our own)
    rooms_from: str  # "segmentation" (Bormann gt_segmentation) or "clearance" (our own)
    room_area_mean_m2: float  # [m^2]
    room_area_max_m2: float  # [m^2]
    corridor_share: float  # [-] share of the room area in elongated rooms (corridors)
    graph_nodes: int  # medial-axis graph: junctions and dead ends
    graph_edges: int  # medial-axis branches between nodes
    graph_cycles: int  # independent loops the robot can close (holes of the free region)
    graph_longest_path_m: float  # [m] longest shortest path along the medial axis
    graph_branch_mean_m: float  # [m] mean branch length
    medial_axis_m: float  # [m] total medial-axis length (the corridors' centre lines)
    clearance_mean_m: float  # [m] distance to the nearest wall, over the region's cells
    clearance_p10_m: float  # [m] 10th percentile
    clearance_p50_m: float  # [m]
    clearance_p90_m: float  # [m]
    openness_m2: float  # [m^2] mean area a laser of laser_range_m sees from a sample point
    openness_share: float  # [-] openness_m2 / free area
    longest_corridor_m: float  # [m] straight extent of the longest corridor (long side of its
    # equivalent rectangle): long featureless straight runs mislead scan matching
    corridor_length_m: float  # [m] total length of the corridors (area / width)
    repeated_room_share: float  # [-] share of rooms that have a near-identical twin
    clutter_share: float  # [-] obstacles inside the building's outline / outline area
    clutter_islands_per_100m2: float  # [1/(100 m^2)] free-standing obstacles per 100 m^2

    def as_dict(self) -> dict[str, float | int | str]:
        """The features as a JSON-ready dict."""
        return dataclasses.asdict(self)


# Name -> (unit, meaning): what `mapqual world info` and the worlds page print.
FEATURE_DOCS: dict[str, tuple[str, str]] = {
    "free_area_m2": ("m^2", "free area of the main region"),
    "perimeter_m": ("m", "boundary length of the free region"),
    "perimeter_per_area": ("1/m", "perimeter / free area"),
    "n_rooms": ("", "rooms"),
    "rooms_from": ("", "where the rooms come from"),
    "room_area_mean_m2": ("m^2", "mean room area"),
    "room_area_max_m2": ("m^2", "largest room"),
    "corridor_share": ("", "share of room area in corridors (elongated rooms)"),
    "graph_nodes": ("", "medial-axis graph: junctions and dead ends"),
    "graph_edges": ("", "medial-axis graph: branches"),
    "graph_cycles": ("", "loops the robot can close"),
    "graph_longest_path_m": ("m", "longest path along the medial axis"),
    "graph_branch_mean_m": ("m", "mean branch length"),
    "medial_axis_m": ("m", "total medial-axis length"),
    "clearance_mean_m": ("m", "mean distance to the nearest wall"),
    "clearance_p10_m": ("m", "10th percentile of the clearance"),
    "clearance_p50_m": ("m", "median clearance"),
    "clearance_p90_m": ("m", "90th percentile of the clearance"),
    "openness_m2": ("m^2", "mean area the laser sees from a point"),
    "openness_share": ("", "openness / free area"),
    "longest_corridor_m": ("m", "longest straight corridor"),
    "corridor_length_m": ("m", "total corridor length"),
    "repeated_room_share": ("", "share of rooms with a near-identical twin"),
    "clutter_share": ("", "free-standing obstacles' share of the outline's area"),
    "clutter_islands_per_100m2": ("1/100 m^2", "free-standing obstacles per 100 m^2"),
}


def numeric_names() -> tuple[str, ...]:
    """The numeric features, in order (what a model reads)."""
    return tuple(f.name for f in dataclasses.fields(WorldFeatures) if f.name != "rooms_from")


def world_features(
    world: World, rooms: np.ndarray | None = None, params: FeatureParams = FeatureParams()
) -> WorldFeatures:
    """The features of `world`; `rooms` `(H, W)` bool marks room cells split at doorways (a
    segmentation image's white, bottom row first), None = segment by clearance.

    Raises InputError when the floorplan has no enclosed free space.
    """
    if not world.facts.main_region_enclosed:
        raise InputError(f"{world.name}: no enclosed free space, so no building to predict for")
    res = world.resolution
    region = _main_region(world)
    area = float(region.sum()) * res * res
    perimeter = fk.boundary_edges(region) * res
    factor = max(
        1, round(params.work_res_m / res), math.ceil(max(region.shape) / params.work_cells)
    )
    work, work_res = fk.coarsen(region, factor), res * factor
    if not work.any():
        raise InputError(f"{world.name}: free space too narrow to analyse at {work_res:g} m")
    work_clear = ndimage.distance_transform_edt(np.pad(work, 1))[1:-1, 1:-1] * work_res
    labels, n, rooms_from = _room_labels(work, work_clear, work_res, rooms, factor, params)
    graph = fk.medial_graph(work, work_res)
    holes = fk.holes(work, params.min_loop_m2 / (work_res * work_res))
    # a regular subsample of the full-resolution clearance (one cell per work cell)
    clear = world.clearance[::factor, ::factor][region[::factor, ::factor]]
    p10, p50, p90 = np.percentile(clear, [10, 50, 90])
    openness = _openness(work, work_clear, work_res, params)
    return WorldFeatures(
        free_area_m2=area,
        perimeter_m=perimeter,
        perimeter_per_area=perimeter / area,
        rooms_from=rooms_from,
        **_room_fields(fk.room_shapes(labels, n, work_res, work_clear), params),
        graph_nodes=graph.nodes,
        graph_edges=graph.edges,
        graph_cycles=holes.loops,
        graph_longest_path_m=graph.longest_path_m,
        graph_branch_mean_m=graph.branch_mean_m,
        medial_axis_m=graph.length_m,
        clearance_mean_m=float(clear.mean()),
        clearance_p10_m=float(p10),
        clearance_p50_m=float(p50),
        clearance_p90_m=float(p90),
        openness_m2=openness,
        openness_share=openness / area,
        clutter_share=holes.share,
        clutter_islands_per_100m2=100.0 * holes.islands / area,
    )


def _main_region(world: World) -> np.ndarray:
    """`(H, W)` bool: the main free region (the largest enclosed one, as the start pose's)."""
    from worker.world import analysis

    labels, n = analysis.free_regions(world.occ)
    label, _ = analysis.main_region(labels, n)
    return labels == label


def _room_labels(
    work: np.ndarray,
    clear: np.ndarray,
    work_res: float,
    rooms: np.ndarray | None,
    factor: int,
    params: FeatureParams,
) -> tuple[np.ndarray, int, str]:
    """(labels (h, w) int, n rooms, source) on the work grid.

    Given `rooms`: its 4-connected patches of at least min_room_m2. Otherwise a
    distance-transform segmentation: one marker per clearance peak (h-maxima: doorways are
    saddles of the clearance), grown over the free space by watershed on the clearance.
    """
    min_cells = params.min_room_m2 / (work_res * work_res)
    if rooms is not None:
        labels, n = ndimage.label(fk.coarsen(rooms, factor) & work, structure=fk._FOUR)
        return (*_drop_small(labels, n, min_cells), "segmentation")
    from skimage.morphology import h_maxima
    from skimage.segmentation import watershed

    # one marker per clearance peak that stands out by room_peak_m from the saddles (doors)
    # around it, in space wider than a door
    peaks = h_maxima(clear, params.room_peak_m).astype(bool) & (clear > params.door_half_width_m)
    cores, n = ndimage.label(peaks, structure=fk._EIGHT)
    if n == 0:
        return np.zeros(work.shape, dtype=np.int32), 0, "clearance"
    labels = watershed(-clear, markers=cores, mask=work)
    return (*_drop_small(labels.astype(np.int32), n, min_cells), "clearance")


def _drop_small(labels: np.ndarray, n: int, min_cells: float) -> tuple[np.ndarray, int]:
    """`labels` with patches under `min_cells` cells removed and the rest renumbered 1..k."""
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    keep = sizes >= min_cells
    keep[0] = False
    new = np.zeros(n + 1, dtype=np.int32)
    new[keep] = np.arange(1, int(keep.sum()) + 1)
    return new[labels], int(keep.sum())


def _room_fields(shapes: fk.RoomShapes, params: FeatureParams) -> dict[str, float | int]:
    """The rooms' and corridors' feature fields."""
    area = shapes.area_m2
    if area.size == 0:
        zero = dict.fromkeys(("room_area_mean_m2", "room_area_max_m2", "corridor_share"), 0.0)
        return {"n_rooms": 0, **zero, "longest_corridor_m": 0.0, "corridor_length_m": 0.0,
                "repeated_room_share": 0.0}  # fmt: skip
    # A strip w wide has mean clearance w/4: a room's width is about 4x its mean clearance and
    # its length its area over that; it is a corridor when length >= elongation x width.
    width = 4.0 * np.maximum(shapes.clear_mean_m, 1e-9)
    length = area / width
    corridor = length >= params.corridor_elongation * width
    return {
        "n_rooms": int(area.size),
        "room_area_mean_m2": float(area.mean()),
        "room_area_max_m2": float(area.max()),
        "corridor_share": float(area[corridor].sum() / area.sum()),
        # straight extent: the equivalent rectangle's long side (an L-shaped corridor's is short)
        "longest_corridor_m": float(shapes.major_m[corridor].max()) if corridor.any() else 0.0,
        "corridor_length_m": float(length[corridor].sum()),
        "repeated_room_share": fk.repeated_share(shapes, params.repeat_tolerance),
    }


def _openness(work: np.ndarray, clear: np.ndarray, work_res: float, params: FeatureParams) -> float:
    """Mean area [m^2] seen by a full-circle laser of laser_range_m from sample points of the
    work grid's free cells where the robot fits (deterministic: drawn with params.seed)."""
    from worker.robot import FOOTPRINT_M
    from worker.world.analysis import footprint_radius
    from worker.world.raycast import cast_scans

    iy, ix = np.nonzero(work & (clear >= footprint_radius(FOOTPRINT_M)))
    if iy.size == 0:
        iy, ix = np.nonzero(work)
    rng = np.random.default_rng(params.seed)
    pick = rng.choice(iy.size, size=min(params.openness_samples, iy.size), replace=False)
    poses = np.column_stack([
        (ix[pick] + 0.5) * work_res, (iy[pick] + 0.5) * work_res, np.zeros(pick.size)
    ])  # fmt: skip
    angles = np.linspace(0.0, 2.0 * math.pi, params.openness_rays, endpoint=False)
    ranges = cast_scans(~work, work_res, 0.0, 0.0, poses, angles, params.laser_range_m)
    return float(fk.polygon_areas(ranges).mean())


def segmentation_rooms(
    world: World, segmentation: str | None = None, *, allow_outside: bool = False
) -> np.ndarray | None:
    """`(H, W)` bool room cells (white of a Bormann gt_segmentation image, bottom row first)
    from `segmentation` or the world's map_server YAML `segmentation:` key; None without one
    or when its size differs from the floorplan's."""
    from pathlib import Path

    from worker.world.image_io import read_grey
    from worker.world.refs import read_map_yaml, yaml_references

    path = Path(segmentation) if segmentation else None
    if path is None and world.source and world.source.endswith((".yaml", ".yml")):
        src = Path(world.source)
        path = yaml_references(src, read_map_yaml(src), allow_outside=allow_outside).get(
            "segmentation"
        )
    if path is None:
        return None
    grey, _ = read_grey(path)
    if grey.shape != world.occ.shape:
        return None
    return np.flipud(grey >= 250)


def features_of(world: World, *, allow_outside: bool = False) -> WorldFeatures:
    """`world_features` with the world's own segmentation where it names one."""
    return world_features(world, segmentation_rooms(world, allow_outside=allow_outside))
