"""Scene layers of the viewer, drawn top-down in the world frame (z up): floorplan, SLAM map
tiles, growing paths, robot markers, scan, goal and plan. Each sends only what changed."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from worker.live_wire import FREE, OCCUPIED

if TYPE_CHECKING:
    import viser

TILE = 128  # [cells] side of a SLAM map tile: a patch re-sends only the tiles it touches
MAX_CHUNKS = 40  # path chunks before they are merged into one node
FLOOR_MAX_PX = 2048  # the floorplan image is shown at most this wide or high
Z_FLOOR, Z_MAP, Z_PATH, Z_ROBOT = 0.0, 0.01, 0.03, 0.05  # [m] layer heights
GT_RGB, EST_RGB = (20, 170, 20), (220, 30, 30)
SCAN_RGB, NAV_GOAL_RGB, NAV_PLAN_RGB = (255, 140, 0), (200, 0, 200), (255, 120, 0)


def _quat_z(theta: float) -> tuple[float, float, float, float]:
    """wxyz of a rotation by theta [rad] about z."""
    return (math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2))


def _segments(points: np.ndarray, z: float) -> np.ndarray:
    """(K, 2) polyline -> (K-1, 2, 3) segments at height z."""
    p = np.column_stack((points, np.full(len(points), z)))
    return np.stack((p[:-1], p[1:]), axis=1).astype(np.float32)


FLOOR_FREE, FLOOR_WALL, BACKGROUND = 235, 95, 250  # greys of the floorplan and of no plan
MAP_FREE_RGB = np.array([120, 170, 255])  # blended half into the floorplan under free cells
MAP_OCC_RGB = np.array([20, 40, 140])


class Floorplan:
    """The world's floorplan as a grey image plane (walls dark grey, free light grey)."""

    def __init__(
        self, scene: viser.SceneApi, name: str, occ: np.ndarray, resolution: float, origin
    ):
        h, w = occ.shape
        self.occ, self.resolution = occ, float(resolution)
        self.origin = (float(origin[0]), float(origin[1]))
        step = max(1, int(math.ceil(max(h, w) / FLOOR_MAX_PX)))
        # bottom row first, as the grid is: viser lays an image's row 0 along the plane's -y
        # edge (its client turns the image plane by pi about x, the camera-image convention)
        shown = occ[::step, ::step]
        img = np.where(shown, FLOOR_WALL, FLOOR_FREE).astype(np.uint8)
        width, height = w * resolution, h * resolution
        centre = (origin[0] + width / 2, origin[1] + height / 2, Z_FLOOR)
        self.node = scene.add_image(
            name, img, width, height, format="png", position=centre, receive_shadow=False
        )
        self.centre = centre[:2]
        self.size = (width, height)

    def grey_at(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """The floorplan's grey at world points [m] (BACKGROUND outside it)."""
        ix = np.floor((x - self.origin[0]) / self.resolution).astype(np.int64)
        iy = np.floor((y - self.origin[1]) / self.resolution).astype(np.int64)
        h, w = self.occ.shape
        inside = (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
        out = np.full(x.shape, BACKGROUND, dtype=np.int64)
        walls = self.occ[np.clip(iy, 0, h - 1), np.clip(ix, 0, w - 1)]
        out[inside] = np.where(walls[inside], FLOOR_WALL, FLOOR_FREE)
        return out


class MapTiles:
    """The SLAM map as opaque image tiles over the floorplan: unknown cells show the floorplan,
    free cells tint it blue, occupied cells are navy.

    Opaque on purpose: the browser sorts translucent planes by their centres, and a tile
    sorted before the floorplan would hide the floorplan under its see-through cells.
    """

    def __init__(self, scene: viser.SceneApi, name: str, visible: bool = True):
        self.scene, self.name = scene, name
        self.visible = visible
        self.floor: Floorplan | None = None
        self.floor_on = True
        self.tiles: dict[tuple[int, int], viser.ImageHandle] = {}
        self.key: tuple | None = None
        self._last: tuple | None = None  # (codes, resolution, origin) last shown

    def show(self, codes: np.ndarray, resolution: float, origin, box=None) -> None:
        """Draw the map; with `box = (iy0, ix0, h, w)` only the tiles that box touches."""
        key = (codes.shape, resolution, tuple(origin))
        if key != self.key:
            self.clear()
            self.key, box = key, None
        self._last = (codes, resolution, origin)
        H, W = codes.shape
        iy0, ix0, h, w = box if box is not None else (0, 0, H, W)
        for ty in range(iy0 // TILE, (iy0 + h - 1) // TILE + 1):
            for tx in range(ix0 // TILE, (ix0 + w - 1) // TILE + 1):
                self._tile(codes, resolution, origin, ty, tx)

    def _tile(self, codes, resolution, origin, ty: int, tx: int) -> None:
        part = codes[ty * TILE : (ty + 1) * TILE, tx * TILE : (tx + 1) * TILE]
        old = self.tiles.pop((ty, tx), None)
        h, w = part.shape
        x0, y0 = origin[0] + tx * TILE * resolution, origin[1] + ty * TILE * resolution
        if old is not None and (part != 0).any() and old.image.shape[:2] == (h, w):
            # new pixels for the same node: the browser keeps showing the old texture until
            # the new one is decoded (a new node is drawn blank white until then)
            old.image = self._rgb(part, resolution, x0, y0)
            self.tiles[(ty, tx)] = old
            return
        if old is not None:
            old.remove()
        if not (part != 0).any():
            return
        self.tiles[(ty, tx)] = self.scene.add_image(
            f"{self.name}/t{ty}_{tx}", self._rgb(part, resolution, x0, y0),
            w * resolution, h * resolution, format="png",
            position=(x0 + w * resolution / 2, y0 + h * resolution / 2, Z_MAP),
            visible=self.visible, receive_shadow=False,
        )  # fmt: skip

    def _rgb(self, part: np.ndarray, resolution: float, x0: float, y0: float) -> np.ndarray:
        """(h, w, 3) uint8, bottom row first (viser's image convention, as the floorplan's),
        of one tile of codes whose lower-left corner is (x0, y0)."""
        h, w = part.shape
        xs = x0 + (np.arange(w) + 0.5) * resolution
        ys = y0 + (np.arange(h) + 0.5) * resolution
        if self.floor is not None and self.floor_on:
            grey = self.floor.grey_at(*np.meshgrid(xs, ys))
        else:
            grey = np.full((h, w), BACKGROUND)
        rgb = np.repeat(grey[..., None], 3, axis=2)
        free, occ = part == FREE, part == OCCUPIED
        rgb[free] = (rgb[free] + MAP_FREE_RGB) // 2
        rgb[occ] = MAP_OCC_RGB
        return np.ascontiguousarray(rgb.astype(np.uint8))

    def set_floor(self, floor: Floorplan | None, on: bool) -> None:
        """The floorplan under unknown cells (redraws every tile when that changes)."""
        self.floor, self.floor_on = floor, on
        if self._last is not None:
            codes, resolution, origin = self._last
            self.show(codes, resolution, origin)

    def set_visible(self, on: bool) -> None:
        self.visible = on
        for node in self.tiles.values():
            node.visible = on

    def clear(self) -> None:
        for node in self.tiles.values():
            node.remove()
        self.tiles.clear()
        self.key = None

    def n_tiles(self) -> int:
        """How many tiles are drawn."""
        return len(self.tiles)


class PathLayer:
    """A polyline that grows: new points become a new line node (only they are sent); every
    MAX_CHUNKS chunks are merged into one node so the scene stays small."""

    def __init__(
        self, scene: viser.SceneApi, name: str, rgb, thickness: float, visible: bool = True
    ):
        self.scene, self.name, self.rgb, self.thickness = scene, name, rgb, thickness
        self.visible = visible
        self.points = np.empty((0, 2))
        self.nodes: list[viser.LineSegmentsHandle] = []
        self._serial = 0

    def set(self, points: np.ndarray) -> None:
        """Replace the whole path."""
        self.clear()
        self.append(points)

    def append(self, points: np.ndarray) -> None:
        """Add points; the new chunk starts at the last point drawn, so the line is unbroken."""
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(points) == 0:
            return
        start = max(0, len(self.points) - 1)
        self.points = np.vstack((self.points, points))
        if len(self.nodes) >= MAX_CHUNKS:
            self.clear_nodes()
            start = 0
        if len(self.points) - start >= 2:
            self.nodes.append(self._node(self.points[start:]))

    def _node(self, pts: np.ndarray) -> viser.LineSegmentsHandle:
        self._serial += 1
        return self.scene.add_line_segments(
            f"{self.name}/c{self._serial}", _segments(pts, Z_PATH), self.rgb,
            thickness=self.thickness, visible=self.visible,
        )  # fmt: skip

    def set_visible(self, on: bool) -> None:
        self.visible = on
        for node in self.nodes:
            node.visible = on

    def clear_nodes(self) -> None:
        for node in self.nodes:
            node.remove()
        self.nodes = []

    def clear(self) -> None:
        self.clear_nodes()
        self.points = np.empty((0, 2))


class Robot:
    """A robot pose as a flat triangle pointing along its heading."""

    def __init__(
        self, scene: viser.SceneApi, name: str, rgb, size: float = 0.45, visible: bool = True
    ):
        verts = np.array([[size, 0, 0], [-size / 2, size / 2, 0], [-size / 2, -size / 2, 0]])
        self.node = scene.add_mesh_simple(
            name, verts.astype(np.float32), np.array([[0, 1, 2]], dtype=np.uint32), color=rgb,
            side="double", position=(0.0, 0.0, Z_ROBOT), visible=False, cast_shadow=False,
        )  # fmt: skip
        self.shown = False
        self.enabled = visible

    def pose(self, x: float, y: float, theta: float) -> None:
        self.node.position = (float(x), float(y), Z_ROBOT)
        self.node.wxyz = _quat_z(float(theta))
        self.shown = True
        self.node.visible = self.enabled

    def set_visible(self, on: bool) -> None:
        self.enabled = on
        self.node.visible = on and self.shown


class Markers:
    """The latest scan (points), the frontier goal (a point) and the global plan (a line)."""

    def __init__(self, scene: viser.SceneApi, name: str, scan_on: bool = True, nav_on: bool = True):
        self.scene, self.name = scene, name
        self.scan = scene.add_point_cloud(
            f"{name}/scan", np.zeros((1, 3), np.float32), SCAN_RGB, point_size=0.08,
            visible=False, point_shape="circle",
        )  # fmt: skip
        self.goal = scene.add_point_cloud(
            f"{name}/goal", np.zeros((1, 3), np.float32), NAV_GOAL_RGB, point_size=0.45,
            visible=False, point_shape="diamond",
        )  # fmt: skip
        self.plan: viser.LineSegmentsHandle | None = None
        self.scan_on, self.nav_on = scan_on, nav_on
        self.has_scan = self.has_goal = False

    def show_scan(self, xy: np.ndarray | None) -> None:
        if xy is None or len(xy) == 0:
            self.has_scan = False
        else:
            self.scan.points = np.column_stack((xy, np.full(len(xy), Z_ROBOT))).astype(np.float32)
            self.has_scan = True
        self.scan.visible = self.scan_on and self.has_scan

    def show_nav(self, goal: np.ndarray | None, plan: np.ndarray | None) -> None:
        self.has_goal = goal is not None
        if goal is not None:
            self.goal.points = np.array([[goal[0], goal[1], Z_ROBOT]], dtype=np.float32)
        self.goal.visible = self.nav_on and self.has_goal
        if self.plan is not None:
            self.plan.remove()
            self.plan = None
        if plan is not None and len(plan) >= 2:
            self.plan = self.scene.add_line_segments(
                f"{self.name}/plan", _segments(plan, Z_PATH + 0.005), NAV_PLAN_RGB,
                thickness=0.05, visible=self.nav_on,
            )  # fmt: skip

    def set_scan_visible(self, on: bool) -> None:
        self.scan_on = on
        self.scan.visible = on and self.has_scan

    def set_nav_visible(self, on: bool) -> None:
        self.nav_on = on
        self.goal.visible = on and self.has_goal
        if self.plan is not None:
            self.plan.visible = on
