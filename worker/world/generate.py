"""Seeded large-building floorplans (a warehouse with aisles, a hospital wing of identical rooms)
written as ordinary map_server worlds, to test how cost and memory grow with a building's size."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from PIL import Image

from worker.errors import InputError

BuildingKind = Literal["warehouse", "hospital"]
KINDS: tuple[BuildingKind, ...] = ("warehouse", "hospital")

FREE_GREY = 254  # map_server's free value; walls are 0
OUTER_WALL_M = 0.3  # [m] outer wall thickness
INNER_WALL_M = 0.2  # [m] partition wall thickness
MIN_SIZE_M = 30.0  # [m] below this neither family has room for its layout
MAX_CELLS = 64_000_000  # the loader's default image limit (worker.world.image_io.MAX_PIXELS)


@dataclass(frozen=True)
class BuildingSpec:
    """What to generate: the family, its outer size and the seed that places everything."""

    kind: BuildingKind = "warehouse"
    width_m: float = 200.0  # [m] along x
    height_m: float = 100.0  # [m] along y
    seed: int = 1
    resolution: float = 0.05  # [m/pixel], the Bormann plans' resolution


class _Plan:
    """A grey image drawn in metres: everything starts as wall, rectangles are carved free.

    Carving only inside the outer wall keeps the building closed, whatever the seed draws.
    """

    def __init__(self, width_m: float, height_m: float, resolution: float):
        self.res = resolution
        self.img = np.zeros(
            (round(height_m / resolution), round(width_m / resolution)), dtype=np.uint8
        )

    def _box(self, x0: float, y0: float, x1: float, y1: float) -> tuple[slice, slice]:
        # image rows grow downwards; the plan is drawn in image axes (x right, y down)
        h, w = self.img.shape
        c0, c1 = (min(max(round(v / self.res), 0), w) for v in (x0, x1))
        r0, r1 = (min(max(round(v / self.res), 0), h) for v in (y0, y1))
        return slice(r0, r1), slice(c0, c1)

    def free(self, x0: float, y0: float, x1: float, y1: float) -> None:
        self.img[self._box(x0, y0, x1, y1)] = FREE_GREY

    def wall(self, x0: float, y0: float, x1: float, y1: float) -> None:
        self.img[self._box(x0, y0, x1, y1)] = 0


def generate(spec: BuildingSpec) -> np.ndarray:
    """The floorplan as a grey image, (rows, cols) uint8: 0 wall, 254 free."""
    _check(spec)
    rng = np.random.default_rng(spec.seed)
    plan = _Plan(spec.width_m, spec.height_m, spec.resolution)
    if spec.kind == "warehouse":
        _warehouse(plan, spec.width_m, spec.height_m, rng)
    else:
        _hospital(plan, spec.width_m, spec.height_m, rng)
    border = OUTER_WALL_M
    plan.wall(0, 0, spec.width_m, border)  # the outer wall, drawn last so nothing breaks it
    plan.wall(0, spec.height_m - border, spec.width_m, spec.height_m)
    plan.wall(0, 0, border, spec.height_m)
    plan.wall(spec.width_m - border, 0, spec.width_m, spec.height_m)
    return plan.img


def _check(spec: BuildingSpec) -> None:
    if spec.kind not in KINDS:
        raise InputError(f"unknown building kind {spec.kind!r} (one of: {', '.join(KINDS)})")
    if not (0.01 <= spec.resolution <= 0.2):
        raise InputError(f"resolution {spec.resolution:g} m/pixel is outside 0.01..0.2")
    for name, size in (("width", spec.width_m), ("height", spec.height_m)):
        if not (math.isfinite(size) and size >= MIN_SIZE_M):
            raise InputError(f"{name} {size:g} m is below the {MIN_SIZE_M:g} m a layout needs")
    cells = (spec.width_m / spec.resolution) * (spec.height_m / spec.resolution)
    if cells > MAX_CELLS:
        raise InputError(f"{cells:,.0f} cells exceed the {MAX_CELLS:,} a world may have")


def _warehouse(plan: _Plan, W: float, H: float, rng: np.random.Generator) -> None:
    """Open hall, an office block in one corner, racks in rows with straight cross aisles."""
    t = OUTER_WALL_M
    plan.free(t, t, W - t, H - t)
    office_w, office_d = float(rng.uniform(0.12, 0.2) * W), 12.0  # [m]
    _office_block(plan, t, t, office_w, office_d, rng)
    aisle = float(rng.uniform(2.8, 3.6))  # [m] between racks, as forklift aisles are
    rack = 2.2  # [m] a double rack, back to back
    y = t + office_d + 5.0  # a 5 m main aisle under the office block
    y_end = H - t - 10.0  # a 10 m dock area along the far wall
    x0, x1 = t + 5.0, W - t - 5.0
    gaps = _cross_aisles(x0, x1, rng)
    while y + rack <= y_end:
        edges = [x0, *[g for gap in gaps for g in gap], x1]
        for a, b in zip(edges[0::2], edges[1::2], strict=True):
            plan.wall(a, y, b, y + rack)
        y += rack + aisle
    _pallets(plan, t, W - t, H - t - 4.0, H - t - 1.0, rng)


def _cross_aisles(x0: float, x1: float, rng: np.random.Generator) -> list[tuple[float, float]]:
    """Straight gaps across every rack row, 3.5 m wide, every 25 to 40 m."""
    gaps, x = [], x0 + float(rng.uniform(25.0, 40.0))
    while x + 3.5 < x1 - 10.0:
        gaps.append((x, x + 3.5))
        x += 3.5 + float(rng.uniform(25.0, 40.0))
    return gaps


def _office_block(
    plan: _Plan, x: float, y: float, w: float, d: float, rng: np.random.Generator
) -> None:
    """Offices along a 2 m corridor, closed to the hall but for one 1.5 m door."""
    wall = INNER_WALL_M
    plan.wall(x, y + d, x + w + wall, y + d + wall)  # the block's wall towards the hall
    plan.wall(x + w, y, x + w + wall, y + d + wall)
    door = float(rng.uniform(x + 2.0, x + w - 3.5))
    plan.free(door, y + d, door + 1.5, y + d + wall)
    corridor_y = y + d - 2.0
    plan.wall(x, corridor_y - wall, x + w, corridor_y)
    room_x = x
    while room_x < x + w - 1e-6:
        left = x + w - room_x
        # the last room takes what is left, so no closed slot without a door remains
        room_w = left if left < 7.0 else float(rng.uniform(3.5, 6.0))
        if room_w < left:
            plan.wall(room_x + room_w - wall, y, room_x + room_w, corridor_y)
        plan.free(room_x + 0.5, corridor_y - wall, room_x + 1.5, corridor_y)
        room_x += room_w


def _pallets(
    plan: _Plan, x0: float, x1: float, y0: float, y1: float, rng: np.random.Generator
) -> None:
    """Pallets 1.2 m x 1.0 m in the dock strip, at least 3 m apart, 1 m from the walls."""
    x = x0 + 1.0 + float(rng.uniform(0.0, 6.0))
    while x + 1.2 < x1 - 1.0:
        if rng.random() < 0.5:
            top = float(rng.uniform(y0, y1 - 1.0))
            plan.wall(x, top, x + 1.2, top + 1.0)
        x += 1.2 + float(rng.uniform(3.0, 8.0))


def _hospital(plan: _Plan, W: float, H: float, rng: np.random.Generator) -> None:
    """Wards of identical rooms on both sides of long corridors, joined by spine corridors."""
    t, wall = OUTER_WALL_M, INNER_WALL_M
    spine = 3.0  # [m] the corridors at both ends that join the wards
    corridor, room_d = 2.4, 5.5  # [m]
    room_w = float(rng.choice([3.6, 4.0, 4.4]))  # [m] one width for every room of the building
    door_at = float(rng.uniform(0.3, room_w - 1.3))  # [m] the same door in every room
    ward = 2 * room_d + corridor + 2 * wall  # [m] rooms, corridor, rooms and their walls
    plan.free(t, t, t + spine, H - t)
    plan.free(W - t - spine, t, W - t, H - t)
    y = t
    while y + ward <= H - t:
        _ward(plan, t + spine + wall, W - t - spine - wall, y, room_w, door_at, rng)
        y += ward + wall  # a wall between one ward's rooms and the next one's
    if H - t - y > 3.0:  # what is left at the far end: a lobby open to both spines
        plan.free(t, y, W - t, H - t)


def _ward(
    plan: _Plan,
    x0: float,
    x1: float,
    y: float,
    room_w: float,
    door_at: float,
    rng: np.random.Generator,
) -> None:
    """One ward: a row of rooms, the corridor, a row of rooms; the corridor meets both spines."""
    wall, corridor, room_d = INNER_WALL_M, 2.4, 5.5
    cy = y + room_d + wall
    plan.free(x0 - wall, cy, x1 + wall, cy + corridor)
    for top, door_y in ((y, cy - wall), (cy + corridor + wall, cy + corridor)):
        x = x0
        while x + room_w <= x1:
            double = rng.random() < 0.08 and x + 2 * room_w + wall <= x1
            w = 2 * room_w + wall if double else room_w
            plan.free(x, top, x + w, top + room_d)
            plan.free(x + door_at, door_y, x + door_at + 1.0, door_y + wall)
            x += w + wall


def write_world(img: np.ndarray, spec: BuildingSpec, out_dir: Path, name: str) -> Path:
    """Write `name.png` and `name.yaml` (map_server) into `out_dir`; returns the YAML's path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(out_dir / f"{name}.png")
    yaml_path = out_dir / f"{name}.yaml"
    yaml_path.write_text(
        f"# generated by `mapqual world generate {spec.kind} --width {spec.width_m:g} "
        f"--height {spec.height_m:g} --seed {spec.seed} --resolution {spec.resolution:g}`\n"
        f"image: {name}.png\n"
        f"resolution: {spec.resolution:g}\n"
        "origin: [0.0, 0.0, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )
    return yaml_path
