"""The viewer's layers in one frame (map_server's: origin lower-left, y up), checked pixel by
pixel in the data the viewer sends, on an L-shaped world defined here by its geometry.

Where a pixel lands is derived by hand from viser's client (1.1.1, ThreeAssets.tsx ViserImage):
the image is a three.js PlaneGeometry of render_width x render_height centred on the node's
position, its texture's row 0 on the plane's +y edge (flipY), and the mesh turned by pi about
x, which puts row 0 on the -y edge. So pixel (row r, column c) of an n_rows x n_cols image
covers x = px - W/2 + (c + [0, 1]) W / n_cols, y = py - H/2 + (r + [0, 1]) H / n_rows.
A vertical flip of the floorplan or of any map tile moves the L's arms and fails these checks.
"""

from __future__ import annotations

import io
import time

import numpy as np
import pytest
from PIL import Image

from frontend.layers import (
    BACKGROUND,
    FLOOR_FREE,
    FLOOR_WALL,
    MAP_FREE_RGB,
    MAP_OCC_RGB,
    Floorplan,
    MapTiles,
    PathLayer,
    Robot,
)
from tests.frontend.conftest import free_port
from worker.live_wire import FREE, OCCUPIED, UNKNOWN

RES, ORIGIN, SHAPE = 0.1, (-1.0, 2.0), (40, 60)  # floorplan: x in [-1, 5], y in [2, 6] m
MAP_RES, MAP_ORIGIN, MAP_SHAPE = 0.02, (-1.1, 1.96), (220, 320)  # 2 x 3 tiles of 128 cells
# the ground truth: down the L's tall arm, then along its foot to the right
WAYPOINTS = np.array([[0.2, 5.0], [0.2, 3.0], [4.0, 3.0]])


def free(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The L: a tall arm on the left (x -0.5..1, y 2.5..5.5), a foot to the right (y 2.5..3.5)."""
    arm = (x > -0.5) & (x < 1.0) & (y > 2.5) & (y < 5.5)
    foot = (x > -0.5) & (x < 4.5) & (y > 2.5) & (y < 3.5)
    return arm | foot


def inside_plan(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return (x > -1.0) & (x < 5.0) & (y > 2.0) & (y < 6.0)


def centres(origin, res: float, shape) -> tuple[np.ndarray, np.ndarray]:
    """World coordinates of the cell centres of a grid [iy, ix], row 0 at the bottom."""
    iy, ix = np.mgrid[0 : shape[0], 0 : shape[1]]
    return origin[0] + (ix + 0.5) * res, origin[1] + (iy + 0.5) * res


def pixels(node) -> np.ndarray:
    """The image exactly as the viewer sent it to the browser."""
    return np.asarray(Image.open(io.BytesIO(node._data)))


def pixel_centres(node, img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World coordinates of each pixel's centre, by viser's convention (module docstring)."""
    n_rows, n_cols = img.shape[:2]
    px, py = float(node.position[0]), float(node.position[1])
    w, h = node.render_width, node.render_height
    r, c = np.mgrid[0:n_rows, 0:n_cols]
    return px - w / 2 + (c + 0.5) * w / n_cols, py - h / 2 + (r + 0.5) * h / n_rows


def pixel_of(node, img: np.ndarray, x, y):
    """(row, column) of the pixel under world point(s) (x, y), by the same convention."""
    n_rows, n_cols = img.shape[:2]
    x0 = float(node.position[0]) - node.render_width / 2
    y0 = float(node.position[1]) - node.render_height / 2
    c = np.floor((np.asarray(x) - x0) / node.render_width * n_cols).astype(int)
    r = np.floor((np.asarray(y) - y0) / node.render_height * n_rows).astype(int)
    return r, c


@pytest.fixture(scope="module")
def server():
    import viser

    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    server.scene.set_up_direction("+z")  # as the viewer's
    yield server
    server.stop()


@pytest.fixture(scope="module")
def scene(server):
    return server.scene


@pytest.fixture(scope="module")
def layers(scene):
    x, y = centres(ORIGIN, RES, SHAPE)
    occ = ~free(x, y)  # [iy, ix] bottom row first, as stored worlds are
    floor = Floorplan(scene, "/align/floor", occ, RES, ORIGIN)
    mx, my = centres(MAP_ORIGIN, MAP_RES, MAP_SHAPE)
    codes = np.where(free(mx, my), FREE, OCCUPIED).astype(np.uint8)
    codes[~inside_plan(mx, my)] = UNKNOWN
    tiles = MapTiles(scene, "/align/map")
    tiles.floor = floor
    tiles.show(codes, MAP_RES, MAP_ORIGIN)
    gt = PathLayer(scene, "/align/gt", (0, 200, 0), 0.05)
    legs = [np.linspace(a, b, 41) for a, b in zip(WAYPOINTS[:-1], WAYPOINTS[1:], strict=True)]
    gt.set(np.vstack(legs))
    robot = Robot(scene, "/align/robot", (0, 200, 0))
    robot.pose(4.0, 3.0, 0.0)
    return floor, tiles, gt, robot


def test_the_floorplan_image_is_the_world_pixel_by_pixel(layers):
    floor = layers[0]
    img = pixels(floor.node)
    assert img.shape == SHAPE  # one pixel per cell
    x, y = pixel_centres(floor.node, img)
    want = np.where(free(x, y), FLOOR_FREE, FLOOR_WALL)
    np.testing.assert_array_equal(img, want)
    # the L's foot runs to the right at the bottom: its far end is free, above it is wall
    assert img[pixel_of(floor.node, img, 4.0, 3.0)] == FLOOR_FREE
    assert img[pixel_of(floor.node, img, 4.0, 5.0)] == FLOOR_WALL


def test_ground_truth_poses_fall_on_free_floorplan_pixels(layers):
    floor, _, gt, robot = layers
    img = pixels(floor.node)
    pts = np.vstack([np.asarray(n.points).reshape(-1, 3) for n in gt.nodes])
    assert len(pts) == 2 * (len(gt.points) - 1)  # both ends of every segment sent
    for x, y, _ in pts:
        assert img[pixel_of(floor.node, img, x, y)] == FLOOR_FREE, (x, y)
    rx, ry = float(robot.node.position[0]), float(robot.node.position[1])
    assert (rx, ry) == (4.0, 3.0)
    assert img[pixel_of(floor.node, img, rx, ry)] == FLOOR_FREE


def test_map_tiles_put_walls_on_the_floorplans_walls(layers):
    floor, tiles, _, _ = layers
    plan = pixels(floor.node)
    assert tiles.n_tiles() == 6
    blended = (FLOOR_FREE + MAP_FREE_RGB) // 2
    walls = 0
    for node in tiles.tiles.values():
        img = pixels(node)
        x, y = pixel_centres(node, img)
        inside = inside_plan(x, y)
        want = np.where(free(x, y)[..., None], blended, MAP_OCC_RGB)
        want[~inside] = BACKGROUND  # unknown cells beyond the plan show no plan
        np.testing.assert_array_equal(img, want)
        # the very same points on the floorplan's image: a wall there is a wall here
        on_wall = (img == MAP_OCC_RGB).all(axis=2)[inside]
        plan_wall = plan[pixel_of(floor.node, plan, x[inside], y[inside])] == FLOOR_WALL
        np.testing.assert_array_equal(on_wall, plan_wall)
        walls += int(on_wall.sum())
    assert walls > 10000


MAGENTA, CYAN = (255, 0, 255), (0, 255, 255)


def _blob(img: np.ndarray, rgb, tol: int = 40) -> np.ndarray:
    """Centre (column, row) [px] of the screenshot's pixels of colour `rgb`."""
    near = (np.abs(img[..., :3].astype(int) - np.array(rgb)) <= tol).all(axis=2)
    rows, cols = np.nonzero(near)
    assert len(rows) > 20, f"no {rgb} marker on the screen"
    return np.array([cols.mean(), rows.mean()])


def _wait_client(server):
    deadline = time.monotonic() + 60
    while not server.get_clients():
        assert time.monotonic() < deadline, "the browser did not connect"
        time.sleep(0.1)
    return next(iter(server.get_clients().values()))


def _probes() -> tuple[np.ndarray, np.ndarray]:
    """World points on a 0.25 m grid, clear of cell edges, the markers, the path and the robot."""
    x, y = np.meshgrid(np.arange(-0.875, 5.0, 0.25), np.arange(2.125, 6.0, 0.25))
    x, y = x.ravel(), y.ravel()
    keep = np.ones(len(x), bool)
    for mx, my in ((4.0, 3.0), (4.0, 5.0)):
        keep &= np.maximum(abs(x - mx), abs(y - my)) > 0.45
    keep &= ~((abs(x - 0.2) < 0.15) & (y > 2.85) & (y < 5.15))  # the path's legs
    keep &= ~((abs(y - 3.0) < 0.15) & (x > 0.05) & (x < 4.6))
    return x[keep], y[keep]


def test_chromium_draws_the_map_walls_where_the_world_has_them(browser, server, layers, artifacts):
    """In the browser, with the viewer's top-down camera: two markers drawn as points (no image
    convention in them) at (4, 3) and (4, 5) give the screen's scale and place; at 300 points
    of a grid over the plan the screen then shows the SLAM map's wall colour exactly where the
    L has walls, its free colour where it is free, and the plan is north up. The tab's title is
    set as the viewer sets it."""
    from frontend.panel import title_html, top_down

    floor = layers[0]
    for name, xy, rgb in (("free", (4.0, 3.0), MAGENTA), ("wall", (4.0, 5.0), CYAN)):
        server.scene.add_point_cloud(
            f"/align/marker_{name}", np.array([[*xy, 0.2]], np.float32), rgb, point_size=0.25,
            point_shape="square",
        )  # fmt: skip
    page = browser.new_page(viewport={"width": 1000, "height": 700})
    page.set_default_timeout(90_000)
    page.goto(f"http://127.0.0.1:{server.get_port()}/")
    client = _wait_client(server)
    top_down(client.camera, floor.centre, floor.size)
    client.gui.add_html(title_html("Run #7 · <L> world"))
    page.wait_for_function("document.title === 'Run #7 · <L> world'")
    close = page.locator(".mantine-Notification-closeButton")  # software-WebGL notice
    for i in range(close.count()):
        close.nth(i).click()
    page.wait_for_timeout(2500)  # the notice fades, the textures are decoded and drawn
    page.screenshot(path=artifacts / "layer-alignment.png")
    img = np.asarray(Image.open(artifacts / "layer-alignment.png").convert("RGB"))
    free_at, wall_at = _blob(img, MAGENTA), _blob(img, CYAN)
    px_per_m = float(np.hypot(*(wall_at - free_at))) / 2.0
    assert px_per_m > 20
    assert wall_at[1] < free_at[1] - 1.9 * px_per_m  # y up: (4, 5) is above (4, 3)
    assert abs(wall_at[0] - free_at[0]) < 0.05 * px_per_m  # north up, not turned
    x, y = _probes()
    assert len(x) > 250
    cols = np.round(free_at[0] + (x - 4.0) * px_per_m).astype(int)
    rows = np.round(free_at[1] - (y - 3.0) * px_per_m).astype(int)
    seen = img[rows, cols].astype(int)
    want = np.where(free(x, y)[:, None], (FLOOR_FREE + MAP_FREE_RGB) // 2, MAP_OCC_RGB)
    wrong = np.abs(seen - want).max(axis=1) > 12
    assert not wrong.any(), list(zip(x[wrong], y[wrong], map(tuple, seen[wrong]), strict=True))
    page.close()
