"""Report images put map cells where map_server would and draw both paths in their colours."""

from __future__ import annotations

import numpy as np
from PIL import Image

from worker.report.plots import errors_png, map_png, trajectories_png, wall_blocks
from worker.slam.grid import ros_to_image


def test_grey_levels_and_orientation_follow_map_saver():
    grid = np.full((4, 3), -1, dtype=np.int8)  # [iy, ix], iy = 0 is the bottom row
    grid[0, 0] = 0  # bottom-left free
    grid[3, 2] = 100  # top-right occupied
    grid[1, 1] = 50  # in between: unknown for map_saver
    grid[2, 0] = 25  # map_saver's threshold_free is 25: still free
    grid[2, 2] = 64  # below threshold_occupied (65): unknown
    grey = ros_to_image(grid)  # image rows: top first
    assert grey[3, 0] == 254
    assert grey[0, 2] == 0
    assert grey[2, 1] == 205
    assert grey[0, 0] == 205
    assert grey[1, 0] == 254 and grey[1, 2] == 205


def test_map_png_is_scaled_by_whole_cells_and_keeps_the_grid(tmp_path):
    grid = np.zeros((100, 160), dtype=np.int8)
    grid[:, 150:] = 100  # a wall band on the right
    path = tmp_path / "map.png"
    map_png(path, grid, ["T mean 0.123 m"], min_width=640)
    img = np.asarray(Image.open(path).convert("L"))
    assert img.shape == (400, 640)  # scale 4
    assert img[-1, -1] == 0 and img[-1, 0] == 254  # bottom row: wall right, free left


def test_trajectories_png_draws_green_ground_truth_and_red_estimate(tmp_path):
    occ = np.zeros((200, 300), dtype=bool)
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    s = np.linspace(1, 14, 300)
    gt = np.column_stack([s, np.full_like(s, 5.0), np.zeros_like(s)])
    est = np.column_stack([s, np.full_like(s, 6.0), np.zeros_like(s)])
    path = tmp_path / "traj.png"
    trajectories_png(path, occ, 0.05, (0.0, 0.0), gt, est)
    rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
    green = (rgb[..., 1] > 120) & (rgb[..., 0] < 80) & (rgb[..., 2] < 80)
    red = (rgb[..., 0] > 150) & (rgb[..., 1] < 110) & (rgb[..., 2] < 110)
    assert green.sum() > 200 and red.sum() > 200
    # the estimate lies above the ground truth (y = 6 vs 5): red rows are higher in the image
    assert np.median(np.nonzero(red)[0]) < np.median(np.nonzero(green)[0])


def test_errors_png_writes_an_image(tmp_path):
    rng = np.random.default_rng(0)
    t2 = rng.uniform(0, 600, 500)
    path = tmp_path / "errors.png"
    errors_png(path, t2, t2 / 600 * rng.uniform(0, 1, 500), rng.uniform(0, 0.02, 500))
    assert Image.open(path).size[0] > 500


def _matplotlib_floorplan(path, occ, resolution, origin, gt, est) -> None:
    """trajectories_png as it was drawn before its colours were looked up once: the plan's
    values through matplotlib's own grey colour map (the independent rendering)."""
    import matplotlib.pyplot as plt

    from worker.report import plots

    def values_through_colour_map(ax, occ, resolution, origin, **_) -> None:
        h, w = occ.shape
        extent = (origin[0], origin[0] + w * resolution, origin[1], origin[1] + h * resolution)
        ax.imshow(np.where(occ, 0.25, 1.0), cmap="gray", vmin=0, vmax=1, origin="lower",
                  extent=extent, interpolation="nearest")  # fmt: skip
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_aspect("equal")

    own = plots._floorplan_axes
    plots._floorplan_axes = values_through_colour_map
    try:
        plots.trajectories_png(path, occ, resolution, origin, gt, est)
    finally:
        plots._floorplan_axes = own
        plt.close("all")


def test_the_floorplan_is_drawn_pixel_for_pixel_as_through_the_colour_map(tmp_path):
    """A plan smaller than the figure (matplotlib maps the values, then scales) and one far
    larger (it scales the colours): the bytes drawn give the same image either way."""
    rng = np.random.default_rng(3)
    for shape in ((60, 90), (1400, 2100)):
        occ = rng.random(shape) < 0.3
        s = np.linspace(1, 4, 50)
        gt = np.column_stack([s, s, np.zeros_like(s)])
        ours, theirs = tmp_path / "ours.png", tmp_path / "theirs.png"
        trajectories_png(ours, occ, 0.05, (-1.0, 2.0), gt, gt + 0.1)
        _matplotlib_floorplan(theirs, occ, 0.05, (-1.0, 2.0), gt, gt + 0.1)
        a = np.asarray(Image.open(ours).convert("RGB"))
        b = np.asarray(Image.open(theirs).convert("RGB"))
        assert a.shape == b.shape
        assert np.array_equal(a, b)
        greys = {tuple(v) for v in a[a.shape[0] // 2, a.shape[1] // 3 : a.shape[1] // 2]}
        assert (64, 64, 64) in greys and (255, 255, 255) in greys  # walls and free space


def test_wall_blocks_mark_a_block_dark_where_any_of_its_cells_is_a_wall():
    rng = np.random.default_rng(5)
    for shape, k in (((7, 11), 3), ((12, 12), 4), ((5, 9), 1), ((1, 13), 5)):
        occ = rng.random(shape) < 0.05
        out = wall_blocks(occ, k)
        hb, wb = -(-shape[0] // k), -(-shape[1] // k)
        assert out.shape == (hb, wb)
        for by in range(hb):
            for bx in range(wb):
                assert out[by, bx] == occ[by * k : (by + 1) * k, bx * k : (bx + 1) * k].any()


def test_a_plan_far_wider_than_the_figure_is_drawn_from_blocks_where_it_lies(tmp_path):
    """4,001 cells across a 990-pixel figure, drawn from 2 x 2 blocks: the walls (1 m thick)
    land on the pixels where matplotlib draws the whole plan cell by cell, within a pixel."""
    occ = np.zeros((400, 4001), dtype=bool)
    occ[:, 1200:1220] = True
    occ[:, 3003:3023] = True
    occ[:20, :] = True
    # a path from the first wall's middle (x = -3 + 1210 * 0.05) to the second's
    gt = np.array([[57.5, 10.0, 0.0], [147.65, 10.0, 0.0]])
    ours, theirs = tmp_path / "ours.png", tmp_path / "theirs.png"
    trajectories_png(ours, occ, 0.05, (-3.0, 1.0), gt, gt)
    _matplotlib_floorplan(theirs, occ, 0.05, (-3.0, 1.0), gt, gt)
    marks = []
    for path in (ours, theirs):
        rgb = np.asarray(Image.open(path).convert("RGB")).astype(int)
        grey = (np.ptp(rgb, axis=2) < 8) & (rgb.max(axis=2) < 100)  # the walls' grey 64
        red = (rgb[..., 0] > 150) & (rgb[..., 1] < 110) & (rgb[..., 2] < 110)
        marks.append([np.flatnonzero(m.any(axis=a)) for m in (grey, red) for a in (0, 1)])
    for a, b in zip(*marks, strict=True):
        assert len(a) and len(b)
        assert abs(a.min() - b.min()) <= 1 and abs(a.max() - b.max()) <= 1
