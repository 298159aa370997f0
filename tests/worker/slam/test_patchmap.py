"""Patch maps: GMapping's scan registration on cells, growth, copy-on-write sharing."""

from __future__ import annotations

import numpy as np
import pytest

from worker.slam.patchmap import PATCH, PatchMaps


def _beam(maps, pose, r, usable=30.0, max_range=29.99):
    ranges = np.array([r])
    maps.register(np.atleast_2d(pose), ranges, np.ones(1), np.zeros(1), usable, max_range)


def test_single_beam_free_cells_and_hit():
    maps = PatchMaps(1, 0.1, 2.0, 0.25)
    # from the centre of cell (0, 0) along +x, 1.03 m: end point x = 1.08 in cell 10
    _beam(maps, [0.05, 0.05, 0.0], 1.03)
    g = maps.occupancy(0)
    assert g.shape == (1, 11)
    assert np.allclose(g.origin, [0.0, 0.0])
    assert np.all(g.prob[0, :10] == 0.0) and g.prob[0, 10] == 1.0
    # the hit's mean position (GMapping's cell.mean()) is kept relative to the cell
    e = maps.tables[0, -maps.tpy0, -maps.tpx0]
    s = maps.hslot[e]
    assert maps.hits[s, 0, 10] == 1 and maps.visits[e, 0, 10] == 1
    assert np.allclose(maps.mean[s, 0, 10], [0.08, 0.05], atol=1e-6)


def test_usable_range_cuts_beam_without_hit_and_max_range_ignores():
    maps = PatchMaps(1, 0.1, 2.0, 0.25)
    _beam(maps, [0.05, 0.05, 0.0], 5.0, usable=1.0)
    g = maps.occupancy(0)
    # cut at 1.0 m: end point x = 1.05 in cell 10, which is not marked (no hit, not free)
    assert g.shape == (1, 10) and np.all(g.prob == 0.0)
    maps2 = PatchMaps(1, 0.1, 2.0, 0.25)
    _beam(maps2, [0.05, 0.05, 0.0], 30.0)  # a no-return reading past maxRange
    assert maps2.occupancy(0).known.sum() == 0


def test_hits_over_visits():
    maps = PatchMaps(1, 0.1, 2.0, 0.25)
    _beam(maps, [0.05, 0.05, 0.0], 0.5)  # hit in cell 5
    _beam(maps, [0.05, 0.05, 0.0], 1.0)  # passes cell 5, hit in cell 10
    _beam(maps, [0.05, 0.05, 0.0], 1.0)
    g = maps.occupancy(0)
    assert np.isclose(g.prob[0, 5], 1 / 3) and g.prob[0, 10] == 1.0
    # the mean of cell 10 over its two hits (both at x = 1.05 + 0.0 in the cell: 0.05)
    e = maps.tables[0, -maps.tpy0, -maps.tpx0]
    s = maps.hslot[e]
    assert maps.hits[s, 0, 10] == 2 and np.allclose(maps.mean[s, 0, 10], [0.05, 0.05], atol=1e-6)


def test_the_map_with_hits_carries_each_cells_end_point_count():
    maps = PatchMaps(1, 0.1, 2.0, 0.25)
    _beam(maps, [0.05, 0.05, 0.0], 0.5)  # ends in cell 5
    _beam(maps, [0.05, 0.05, 0.0], 1.0)  # through cell 5, ends in cell 10
    _beam(maps, [0.05, 0.05, 0.0], 1.0)
    g = maps.occupancy(0, with_hits=True)
    assert maps.occupancy(0).hits is None  # only when asked: the explore loop's maps skip it
    expected = np.zeros((1, 11), np.float32)
    expected[0, 5], expected[0, 10] = 1, 2
    assert g.hits.dtype == np.float32 and np.array_equal(g.hits, expected)
    assert np.array_equal(g.prob, maps.occupancy(0).prob)
    with pytest.raises(ValueError):
        g.hits[0, 0] = 1.0  # read-only, as prob


def test_map_grows_with_explored_area_negative_side():
    maps = PatchMaps(1, 0.05, 1.0, 0.25)
    _beam(maps, [0.01, 0.01, 0.0], 1.0)
    before = maps.tables.shape
    maps.register(np.array([[-20.0, -20.0, np.pi]]), np.array([3.0]), np.ones(1), np.zeros(1),
                  30.0, 29.99)  # fmt: skip
    assert maps.tables.shape[1] > before[1] and maps.tables.shape[2] > before[2]
    g = maps.occupancy(0)
    # both beams are in the map: the old one at y ~ 0 and the new one ending at x = -23.0
    hits = np.argwhere(g.prob == 1.0)
    xs = g.origin[0] + (hits[:, 1] + 0.5) * g.resolution
    assert np.isclose(xs.min(), -23.0 + 0.025, atol=0.05) and np.isclose(xs.max(), 1.0, atol=0.05)


def test_copy_on_write_sharing():
    maps = PatchMaps(3, 0.05, 1.0, 0.25)
    ranges = np.full(8, 1.0)  # 20 cells: stays in the 4 patches around the origin
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    poses = np.zeros((3, 3))
    maps.register(poses, ranges, np.cos(angles), np.sin(angles), 30.0, 29.99)
    live = maps.live_patches()
    assert live == 3 * 4  # each particle owns the four patches around the origin
    maps.select(np.array([1, 1, 1]))  # resampling: no patch copied, all shared
    assert maps.live_patches() == 4
    assert np.all(maps.counts[maps.counts > 0] == 3)
    # each particle registers a beam from its own pose; all write in the origin's patch only,
    # so that patch is copied three times and the old shared one is freed: 3 shared + 3 own
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 0.5, 0.0], [0.0, 1.0, 0.0]])
    maps.register(poses, np.array([1.0]), np.ones(1), np.zeros(1), 30.0, 29.99)
    assert maps.live_patches() == 6
    assert np.all(maps.counts[maps.counts > 0] <= 3)
    differ = maps.tables[0] != maps.tables[1]
    assert differ.sum() == 1 and np.array_equal(differ, maps.tables[1] != maps.tables[2])
    p0, p1 = maps.occupancy(0), maps.occupancy(1)
    # the beam at y = 0.5 is in particle 1's map only (cell (14, 10): off the diagonals)
    cell = p1.world_to_cell(np.array([[0.7, 0.5]]))[0]
    assert p1.prob[cell[1], cell[0]] == 0.0
    cell = p0.world_to_cell(np.array([[0.7, 0.5]]))[0]
    assert np.isnan(p0.prob[cell[1], cell[0]])
    assert maps.dropped == 0
    assert PATCH == 32


def test_copies_of_one_particle_register_once_and_share_the_result():
    rng = np.random.default_rng(3)
    angles = np.linspace(-2.3, 2.3, 91)
    first = np.array([[0.3, 0.2, 0.1], [0.9, -0.4, 1.2]])
    scan = rng.uniform(0.5, 6.0, angles.size)
    idx = np.array([0, 0, 1, 1, 1])  # resampling: two copies of particle 0, three of 1
    poses = first[idx]
    plain, shared = PatchMaps(2, 0.05, 1.0, 0.25), PatchMaps(2, 0.05, 1.0, 0.25)
    for maps in (plain, shared):
        maps.register(first, scan, np.cos(angles), np.sin(angles), 30.0, 29.99)
        maps.select(idx)
    plain.register(poses, scan[::-1], np.cos(angles), np.sin(angles), 30.0, 29.99)
    shared.register(poses, scan[::-1], np.cos(angles), np.sin(angles), 30.0, 29.99,
                    same_as=np.array([0, 0, 2, 2, 2]))  # fmt: skip
    for k in range(5):  # every particle's map is the one it would have written itself
        a, b = plain.occupancy(k), shared.occupancy(k)
        assert np.array_equal(a.prob, b.prob, equal_nan=True) and np.allclose(a.origin, b.origin)
    # registered twice, not five times: the copies hold the same patches
    assert np.array_equal(shared.tables[0], shared.tables[1])
    assert shared.live_patches() < plain.live_patches()
    assert np.array_equal(shared.counts, np.bincount(shared.tables[shared.tables >= 0].ravel(),
                                                     minlength=shared.capacity))  # fmt: skip
    with pytest.raises(ValueError, match="same_as"):  # particles 0 and 2 differ
        shared.register(poses, scan, np.cos(angles), np.sin(angles), 30.0, 29.99,
                        same_as=np.array([0, 0, 0, 2, 2]))  # fmt: skip


def _planes(maps, k):
    """Particle k's cells as dense planes (visits, hits, mean, bits), empty where no patch."""
    th, tw = maps.tables.shape[1:]
    cells = (th, tw, PATCH, PATCH)
    out = (np.zeros(cells), np.zeros(cells), np.zeros((*cells, 2)),
           np.zeros((th, tw, 2, PATCH), dtype=np.int64))  # fmt: skip
    for ty in range(th):
        for tx in range(tw):
            e = maps.tables[k, ty, tx]
            if e >= 0:
                out[0][ty, tx] = maps.visits[e]
                s = maps.hslot[e]
                if s >= 0:  # no slot: no hit, all zeros
                    for plane, src in zip(out[1:], (maps.hits, maps.mean, maps.bits), strict=True):
                        plane[ty, tx] = src[s]
    return out


def test_parallel_registration_writes_the_same_cells():
    # particles spread over a few metres, scans of 360 beams up to 12 m (lines across many
    # patch borders at every angle, cut at usable range 8 m, some past max range), with
    # resampling between updates (shared patches to copy on write): every particle's cells,
    # hit means and bit masks equal the serial registration's
    rng = np.random.default_rng(11)
    n = 12
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    serial, parallel = PatchMaps(n, 0.05, 2.0, 0.25), PatchMaps(n, 0.05, 2.0, 0.25)
    # off the origin, so that the table's first patch column and row differ (tpx0 != tpy0)
    xy = rng.uniform(-2, 2, (n, 2)) + [9.0, -4.0]
    poses = np.column_stack([xy, rng.uniform(-np.pi, np.pi, n)])
    for _ in range(6):
        scan = rng.uniform(0.3, 12.0, angles.size)
        scan[rng.random(angles.size) < 0.05] = 0.0  # no reading
        for maps, par in ((serial, False), (parallel, True)):
            maps.register(poses, scan, np.cos(angles), np.sin(angles), 8.0, 11.5, parallel=par)
        idx = np.sort(rng.integers(0, n, n))
        for maps in (serial, parallel):
            maps.select(idx)
        poses = poses[idx] + rng.normal(0, [0.3, 0.3, 0.2], (n, 3))
    assert serial.tpx0 == parallel.tpx0 and serial.tpy0 == parallel.tpy0
    assert serial.tpx0 != serial.tpy0
    for k in range(n):
        for a, b in zip(_planes(serial, k), _planes(parallel, k), strict=True):
            assert np.array_equal(a, b)
        ga, gb = serial.occupancy(k, with_hits=True), parallel.occupancy(k, with_hits=True)
        assert np.array_equal(ga.prob, gb.prob, equal_nan=True)
        assert np.allclose(ga.origin, gb.origin) and np.array_equal(ga.hits, gb.hits)
    assert serial.dropped == parallel.dropped == 0
    # the claim takes a few patches the lines miss (copies or empty), no more
    assert serial.live_patches() <= parallel.live_patches() <= 1.2 * serial.live_patches()


def test_hit_slots_only_for_patches_where_a_beam_ended():
    # one beam along +x from the origin, 4 m at 0.05 m: 80 cells over three patches; only the
    # last holds the end point, so one hit slot for three patches
    maps = PatchMaps(1, 0.05, 1.0, 0.25)
    _beam(maps, [0.01, 0.01, 0.0], 4.0)
    assert maps.live_patches() == 3 and maps.live_hit_slots() == 1
    row = maps.tables[0, -maps.tpy0, -maps.tpx0 : -maps.tpx0 + 3]
    assert list(maps.hslot[row] >= 0) == [False, False, True]
    # the matcher's tables see only that patch
    assert np.count_nonzero(maps.match_tables()[0] >= 0) == 1
    # a beam cut at the usable range marks free cells only: no slot
    _beam(maps, [0.01, 0.01, np.pi / 2], 5.0, usable=3.0)
    assert maps.live_hit_slots() == 1 and maps.live_patches() > 3


def test_copied_patches_get_their_own_hit_slots():
    rng = np.random.default_rng(5)
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    maps = PatchMaps(4, 0.05, 1.0, 0.25)
    poses = np.zeros((4, 3))
    for _ in range(8):
        scan = rng.uniform(4.0, 6.0, angles.size)  # the patches around the robot only crossed
        maps.register(poses, scan, np.cos(angles), np.sin(angles), 30.0, 29.99)
        maps.select(np.sort(rng.integers(0, 4, 4)))
        poses = poses + rng.normal(0, 0.2, (4, 3))
        live = maps.counts > 0
        slots = maps.hslot[live][maps.hslot[live] >= 0]
        # a slot belongs to one live patch; no more slots than patches with a hit
        assert np.unique(slots).size == slots.size
        with_hits = [e for e in np.flatnonzero(live) if maps.hslot[e] >= 0]
        for e in with_hits:
            assert maps.hits[maps.hslot[e]].sum() > 0
    # the patches within 4 m of the robot are only crossed by beams: they have no slot
    assert maps.live_hit_slots() < maps.live_patches()
    assert maps.dropped == 0
