"""Issue 52: the navigation's per-update work follows what changed, and its results equal a
computation from scratch (random map edits, each re-read through its own window only)."""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import ndimage

from worker.explore.costmap import GlobalCostmap, cost_from_distance
from worker.explore.frontiers import FrontierSearch
from worker.explore.params import ExploreParams

RES = 0.05
H, W = 56, 64
ORIGIN = (1.0, -2.0)
FREE, OCC = 0.05, 0.9

# one edit: a rectangle (y0, x0, height, width) set to unknown, free or occupied
edit = st.tuples(
    st.integers(0, H - 1),
    st.integers(0, W - 1),
    st.integers(1, 12),
    st.integers(1, 12),
    st.sampled_from([np.nan, FREE, OCC]),
)
SETTINGS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _apply(prob: np.ndarray, e) -> tuple[float, float, float, float]:
    """Write edit `e` into prob; the window [m] that holds it (as the loop's beam box)."""
    y0, x0, h, w, value = e
    y1, x1 = min(H, y0 + h), min(W, x0 + w)
    prob[y0:y1, x0:x1] = value
    return (
        ORIGIN[0] + x0 * RES,
        ORIGIN[1] + y0 * RES,
        ORIGIN[0] + (x1 - 0.5) * RES,
        ORIGIN[1] + (y1 - 0.5) * RES,
    )


def _edited(edits) -> tuple[GlobalCostmap, FrontierSearch, np.ndarray]:
    """A costmap and frontier search fed the edits one window at a time (the first update
    reads the whole map, as the navigator's does), and the final map."""
    p = ExploreParams()
    prob = np.full((H, W), np.nan, dtype=np.float32)
    prob[20:36, 24:40] = FREE  # a known room to start from
    cm, fs = GlobalCostmap(p.costmap, p.doors.door_align), FrontierSearch(p.frontiers, p.planner)
    fs.update(cm, cm.update(prob, RES, ORIGIN))
    for e in edits:
        window = _apply(prob, e)
        fs.update(cm, cm.update(prob, RES, ORIGIN, window_m=window))
    return cm, fs, prob


@SETTINGS
@given(st.lists(edit, min_size=1, max_size=12))
def test_windowed_updates_equal_a_costmap_built_from_scratch(edits):
    cm, _, prob = _edited(edits)
    fresh = GlobalCostmap(ExploreParams().costmap)
    fresh.update(prob, RES, ORIGIN)
    np.testing.assert_array_equal(cm.lethal, fresh.lethal)
    np.testing.assert_array_equal(cm.unknown, fresh.unknown)
    np.testing.assert_array_equal(cm.inflated, fresh.inflated)
    # and the costs are costmap_2d's by the exact distance to the nearest obstacle (float
    # rounding may move a value across an integer by one)
    occupied = ~np.isnan(prob) & (prob > 0.25)
    if occupied.any():
        dist = ndimage.distance_transform_edt(~occupied) * RES
        expected = cost_from_distance(dist, 0.2, 7.5, 2.25).astype(int)
        assert np.max(np.abs(expected - cm.inflated.astype(int))) <= 1
    else:
        assert not cm.inflated.any()


@SETTINGS
@given(st.lists(edit, min_size=1, max_size=12))
def test_frontier_updates_equal_frontiers_found_from_scratch(edits):
    cm, fs, prob = _edited(edits)
    unknown = np.isnan(prob)
    free = ~unknown & ~(prob > 0.25)
    pad = np.pad(unknown, 1, constant_values=False)
    near_unknown = pad[:-2, 1:-1] | pad[2:, 1:-1] | pad[1:-1, :-2] | pad[1:-1, 2:]
    expected = free & near_unknown
    np.testing.assert_array_equal(fs.frontier, expected)
    assert fs.n_frontier_cells == int(expected.sum())
    # the clusters read inside the frontier's box: every cell, in row-major order, labelled
    # as an 8-connected labelling numbers them (by first cell in raster order)
    cells, labels = fs.clusters()
    np.testing.assert_array_equal(cells, np.argwhere(expected))
    lab, _ = ndimage.label(expected, structure=np.ones((3, 3)))
    np.testing.assert_array_equal(labels, lab[expected] - 1)


def test_live_coverage_counts_the_reachable_cells_on_free_map_cells():
    from worker.evaluate.coverage import ReachCells

    # a 10 x 10 world, all reachable; the map (same grid) free in its left half only
    reach = np.ones((10, 10), dtype=bool)
    prob = np.full((10, 10), np.nan, dtype=np.float32)
    prob[:, :5] = 0.1
    cells = ReachCells(reach, RES, np.zeros(2))
    assert cells.coverage(prob, RES, np.zeros(2), 0.25, np.zeros(3)) == 0.5
    # the map placed 7 cells to the right in the world: world columns 7-9 fall on its free
    # columns 0-2, the rest off the map or on unknown cells
    T = np.array([7 * RES, 0.0, 0.0])
    assert cells.coverage(prob, RES, np.zeros(2), 0.25, T) == 0.3
    prob[:, 1] = 0.9  # an occupied column is not free
    assert cells.coverage(prob, RES, np.zeros(2), 0.25, T) == 0.2


def _stamped(lethal: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """The definition of the inflation: every obstacle's kernel stamp, the maximum of them."""
    r = kernel.shape[0] // 2
    h, w = lethal.shape
    out = np.zeros((h + 2 * r, w + 2 * r), dtype=np.uint8)
    for y, x in np.argwhere(lethal):
        np.maximum(
            out[y : y + 2 * r + 1, x : x + 2 * r + 1],
            kernel,
            out=out[y : y + 2 * r + 1, x : x + 2 * r + 1],
        )
    return out[r : r + h, r : r + w]


@SETTINGS
@given(
    st.integers(0, 2**32 - 1),
    st.sampled_from([(0.05, 0.2, 7.5, 2.25), (0.1, 0.3, 3.0, 1.0), (0.05, 0.1, 20.0, 0.4)]),
    st.floats(0.0, 0.08),
    st.tuples(st.integers(0, 70), st.integers(0, 70), st.integers(0, 90), st.integers(0, 90)),
)
def test_region_inflation_equals_the_kernels_stamped_at_every_obstacle(seed, kp, density, box):
    from worker.explore import costmap_kernels as ck

    rng = np.random.default_rng(seed)
    lethal = rng.random((70, 90)) < density
    lethal[rng.integers(0, 70), :] = True  # a wall across, with gaps
    lethal[:, rng.integers(0, 90)] &= rng.random(70) < 0.5
    kernel = ck.inflation_kernel(*kp)
    cost = np.full(lethal.shape, 77, dtype=np.uint8)  # stale costs outside the region stay
    y0, y1 = sorted(box[:2])
    x0, x1 = sorted(box[2:])
    ck.inflate_region(lethal, kernel, cost, y0, y1, x0, x1)
    expected = np.full(lethal.shape, 77, dtype=np.uint8)
    expected[y0:y1, x0:x1] = _stamped(lethal, kernel)[y0:y1, x0:x1]
    np.testing.assert_array_equal(cost, expected)
