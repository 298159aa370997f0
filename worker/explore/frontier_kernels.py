"""Numba kernels of the frontier search: frontier cells, clusters, goal candidate stamping."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def update_frontier_region(lethal, unknown, frontier, counts, tile, y0, y1, x0, x1):
    """Recompute `frontier[y0:y1, x0:x1]` in place: known free cells with an unknown 4-neighbour.

    lethal, unknown, frontier: (H, W) bool; counts: (ceil(H / tile), ceil(W / tile)) int32,
    the frontier cells of each `tile x tile` block, kept up to date here. Returns the change
    in the number of frontier cells.
    """
    h, w = lethal.shape
    delta = 0
    for iy in range(y0, y1):
        for ix in range(x0, x1):
            f = False
            if not unknown[iy, ix] and not lethal[iy, ix]:
                f = (
                    (iy > 0 and unknown[iy - 1, ix])
                    or (iy < h - 1 and unknown[iy + 1, ix])
                    or (ix > 0 and unknown[iy, ix - 1])
                    or (ix < w - 1 and unknown[iy, ix + 1])
                )
            if f != frontier[iy, ix]:
                d = 1 if f else -1
                delta += d
                counts[iy // tile, ix // tile] += d
                frontier[iy, ix] = f
    return delta


@njit(cache=True)
def frontier_cells(frontier, counts, tile, n):
    """`(n, 2) int64 [iy, ix]` the n frontier cells in row-major order (np.argwhere's), read
    from the blocks that hold some (`counts`, see update_frontier_region): the work follows
    the frontier, not the grid."""
    h, w = frontier.shape
    th, tw = counts.shape
    out = np.empty((n, 2), dtype=np.int64)
    busy = np.empty(tw, dtype=np.int64)
    k = 0
    for ty in range(th):
        m = 0
        for tx in range(tw):
            if counts[ty, tx] > 0:
                busy[m] = tx
                m += 1
        if m == 0:
            continue
        for iy in range(ty * tile, min(h, (ty + 1) * tile)):
            for j in range(m):
                tx = busy[j]
                for ix in range(tx * tile, min(w, (tx + 1) * tile)):
                    if frontier[iy, ix] and k < n:
                        out[k, 0] = iy
                        out[k, 1] = ix
                        k += 1
    return out[:k]


@njit(cache=True)
def label_clusters(frontier, cells, labels_buf, stamp, run_id):
    """8-connected clusters of frontier cells.

    cells: (K, 2) int64 [iy, ix] of every frontier cell. labels_buf, stamp: (H, W) int32 reusable
    buffers (valid where stamp == run_id). Returns `(K,) int64` cluster label per cell, 0-based.
    """
    h, w = frontier.shape
    k = cells.shape[0]
    for i in range(k):
        iy = cells[i, 0]
        ix = cells[i, 1]
        stamp[iy, ix] = run_id
        labels_buf[iy, ix] = -1
    out = np.empty(k, dtype=np.int64)
    queue = np.empty(k, dtype=np.int64)
    n_labels = 0
    for i in range(k):
        sy = cells[i, 0]
        sx = cells[i, 1]
        if labels_buf[sy, sx] >= 0:
            continue
        labels_buf[sy, sx] = n_labels
        head = 0
        tail = 0
        queue[tail] = sy * w + sx
        tail += 1
        while head < tail:
            idx = queue[head]
            head += 1
            iy = idx // w
            ix = idx - iy * w
            for dy in range(-1, 2):
                for dx in range(-1, 2):
                    jy = iy + dy
                    jx = ix + dx
                    if jy < 0 or jy >= h or jx < 0 or jx >= w:
                        continue
                    if stamp[jy, jx] == run_id and labels_buf[jy, jx] < 0:
                        labels_buf[jy, jx] = n_labels
                        queue[tail] = jy * w + jx
                        tail += 1
        n_labels += 1
    for i in range(k):
        out[i] = labels_buf[cells[i, 0], cells[i, 1]]
    return out


@njit(cache=True)
def stamp_targets(
    cells, cell_cluster, cell_valid, offsets, inflated, unknown, target, owner, blocked
):
    """Mark goal candidates: passable known cells within the goal radius of a valid frontier cell.

    cells: (K, 2) [iy, ix] frontier cells; cell_cluster: (K,) their cluster; cell_valid: (K,)
    bool (cluster big enough, not blacklisted); offsets: (M, 2) [dy, dx] of the goal disc.
    target (H, W) bool and owner (H, W) int32 (cluster of each candidate) are written; returns
    the (N, 2) [iy, ix] cells marked, so that the caller can unmark them afterwards without
    clearing the whole grid.
    """
    h, w = target.shape
    marked = np.empty((1024, 2), dtype=np.int64)
    n = 0
    seen = np.zeros(cell_cluster.max() + 1 if cell_cluster.shape[0] else 1, dtype=np.int64)
    # candidates on the even sub-lattice only (a goal needs no finer placement than 2 cells):
    # the offsets split by parity, in their order, so each cell visits only the quarter
    # that lands on it
    n_off = offsets.shape[0]
    by_parity = np.empty((4, n_off, 2), dtype=np.int64)
    n_par = np.zeros(4, dtype=np.int64)
    for m in range(n_off):
        k = ((offsets[m, 0] & 1) << 1) | (offsets[m, 1] & 1)
        by_parity[k, n_par[k], 0] = offsets[m, 0]
        by_parity[k, n_par[k], 1] = offsets[m, 1]
        n_par[k] += 1
    for i in range(cells.shape[0]):
        c = cell_cluster[i]
        if not cell_valid[i]:
            continue
        # every third cell of a cluster is enough: the goal discs (radius >> 3 cells) overlap
        seen[c] += 1
        if (seen[c] - 1) % 3 != 0:
            continue
        k = ((cells[i, 0] & 1) << 1) | (cells[i, 1] & 1)
        for m in range(n_par[k]):
            jy = cells[i, 0] + by_parity[k, m, 0]
            jx = cells[i, 1] + by_parity[k, m, 1]
            if jy < 0 or jy >= h or jx < 0 or jx >= w or target[jy, jx]:
                continue
            if unknown[jy, jx] or inflated[jy, jx] >= blocked:
                continue
            target[jy, jx] = True
            owner[jy, jx] = c
            if n == marked.shape[0]:
                m2 = np.empty((2 * n, 2), dtype=np.int64)
                m2[:n] = marked
                marked = m2
            marked[n, 0] = jy
            marked[n, 1] = jx
            n += 1
    return marked[:n]


@njit(cache=True)
def any_in_disc(mask, iy, ix, offsets):
    """True when some cell of `mask (H, W) bool` lies in the disc `offsets` around (iy, ix)."""
    h, w = mask.shape
    for m in range(offsets.shape[0]):
        jy = iy + offsets[m, 0]
        jx = ix + offsets[m, 1]
        if 0 <= jy < h and 0 <= jx < w and mask[jy, jx]:
            return True
    return False


@njit(cache=True)
def line_of_sight(lethal, unknown, y0, x0, y1, x1):
    """True when the straight line between two cells crosses only known free cells
    (Bresenham; the end cells themselves are not tested)."""
    dx = abs(x1 - x0)
    dy = -abs(y1 - y0)
    sx = 1 if x0 < x1 else -1
    sy = 1 if y0 < y1 else -1
    err = dx + dy
    x = x0
    y = y0
    while True:
        if x == x1 and y == y1:
            return True
        if (x != x0 or y != y0) and (lethal[y, x] or unknown[y, x]):
            return False
        e2 = 2 * err
        if e2 >= dy:
            err += dy
            x += sx
        if e2 <= dx:
            err += dx
            y += sy


@njit(cache=True)
def first_with_sight(order, cand, members, lethal, unknown, width, max_tries):
    """Index into `order` of the first candidate cell that sees a frontier cell of its cluster.

    order: (K,) candidate indices, best first; cand: (N,) flat indices of candidate cells;
    members: (M, 2) [iy, ix] frontier cells of the cluster. Each candidate is tested against
    its nearest frontier cells (up to 8). Returns -1 when none of the first max_tries does.
    """
    m = members.shape[0]
    d2 = np.empty(m)
    for k in range(min(order.shape[0], max_tries)):
        idx = cand[order[k]]
        cy = idx // width
        cx = idx - cy * width
        for j in range(m):
            d2[j] = (members[j, 0] - cy) ** 2 + (members[j, 1] - cx) ** 2
        nearest = np.argsort(d2)[:8]
        for j in nearest:
            if line_of_sight(lethal, unknown, cy, cx, members[j, 0], members[j, 1]):
                return k
    return -1


@njit(cache=True)
def open_frontier_cells(cells, unknown, state, stamp, run_id, max_cells):
    """Which frontier cells border unknown space larger than `max_cells` cells.

    cells: (K, 2) int64 [iy, ix] frontier cells; unknown: (H, W) bool. An unknown region
    (4-connected) of at most max_cells cells is enclosed by known cells: the inside of a
    table leg or a wall the laser never sees into, which no viewpoint can ever reveal, so
    the free cells next to it are no frontier. The grid's edge counts as open. state (H, W)
    int8 and stamp (H, W) int32 are reusable buffers (valid where stamp == run_id): each
    region is flooded once, at most max_cells + 1 cells deep. Returns `(K,) bool`.
    """
    h, w = unknown.shape
    out = np.zeros(cells.shape[0], dtype=np.bool_)
    queue = np.empty(max_cells + 8, dtype=np.int64)
    for i in range(cells.shape[0]):
        cy = cells[i, 0]
        cx = cells[i, 1]
        for k in range(4):
            sy = cy + (1 if k == 0 else (-1 if k == 1 else 0))
            sx = cx + (1 if k == 2 else (-1 if k == 3 else 0))
            if sy < 0 or sy >= h or sx < 0 or sx >= w:
                out[i] = True
                break
            if not unknown[sy, sx]:
                continue
            if stamp[sy, sx] != run_id:
                _flood_unknown(unknown, state, stamp, run_id, sy, sx, queue, max_cells)
            if state[sy, sx] == 2:
                out[i] = True
                break
    return out


@njit(cache=True)
def _flood_unknown(unknown, state, stamp, run_id, sy, sx, queue, max_cells):
    """Label the unknown region holding (sy, sx): state 1 small (enclosed), 2 large."""
    h, w = unknown.shape
    head = 0
    tail = 0
    stamp[sy, sx] = run_id
    state[sy, sx] = 3  # being flooded
    queue[tail] = sy * w + sx
    tail += 1
    large = False
    while head < tail and not large:
        idx = queue[head]
        head += 1
        iy = idx // w
        ix = idx - iy * w
        for k in range(4):
            jy = iy + (1 if k == 0 else (-1 if k == 1 else 0))
            jx = ix + (1 if k == 2 else (-1 if k == 3 else 0))
            if jy < 0 or jy >= h or jx < 0 or jx >= w:
                large = True
                break
            if not unknown[jy, jx]:
                continue
            if stamp[jy, jx] == run_id:
                if state[jy, jx] == 2:
                    large = True
                    break
                continue
            if tail > max_cells:
                large = True
                break
            stamp[jy, jx] = run_id
            state[jy, jx] = 3
            queue[tail] = jy * w + jx
            tail += 1
    result = 2 if large else 1
    for q in range(tail):
        idx = queue[q]
        iy = idx // w
        state[iy, idx - iy * w] = result


@njit(cache=True)
def observe_frontier(frontier, lethal, unknown, seen, ry, rx, rth, radius, half_fov, looks):
    """Count a close look at each frontier cell the robot at cell (ry, rx), heading rth [rad],
    sees now: within `radius` cells, inside the laser's field of view (+-half_fov [rad]) and
    with a line of sight over known free cells. seen: (H, W) uint8, saturating. Returns how
    many cells' counts reached `looks` (the count that makes a frontier cell dead)."""
    h, w = frontier.shape
    r = int(radius)
    n = 0
    for jy in range(max(0, ry - r), min(h, ry + r + 1)):
        for jx in range(max(0, rx - r), min(w, rx + r + 1)):
            if not frontier[jy, jx] or seen[jy, jx] == 255:
                continue
            dy = jy - ry
            dx = jx - rx
            if dx * dx + dy * dy > radius * radius:
                continue
            a = math.atan2(dy, dx) - rth
            a = (a + math.pi) % (2.0 * math.pi) - math.pi
            if abs(a) > half_fov:
                continue
            if line_of_sight(lethal, unknown, ry, rx, jy, jx):
                seen[jy, jx] += 1
                if seen[jy, jx] == looks:
                    n += 1
    return n


@njit(cache=True)
def nearest_distance2(cy, cx, members):
    """Squared distance [cells^2] from each cell `(cy[k], cx[k])` to the nearest of `members
    (M, 2) [iy, ix]`; `(K,)` float64 (inf when there are no members)."""
    out = np.full(cy.shape[0], np.inf)
    for k in range(cy.shape[0]):
        best = np.inf
        for j in range(members.shape[0]):
            dy = float(members[j, 0] - cy[k])
            dx = float(members[j, 1] - cx[k])
            d2 = dy * dy + dx * dx
            if d2 < best:
                best = d2
        out[k] = best
    return out


def within_radius(xs: np.ndarray, ys: np.ndarray, points, radius: float) -> np.ndarray:
    """`(K,) bool`: the positions `(xs, ys) (K,)` [m] with `hypot(x - px, y - py) <= radius` for
    some point `(px, py)` of `points`. Each point tests only the positions of its x band, found
    in the positions sorted by x (the band is 1e-6 m wider than the radius, far beyond
    rounding at a building's coordinates), with the same test: the cells a blacklist or the
    spent frontier cells leave alone, without a map-wide pass per point."""
    near = np.zeros(len(xs), dtype=np.bool_)
    if len(points) == 0 or len(xs) == 0:
        return near
    order = np.argsort(xs, kind="stable")
    sorted_x = xs[order]
    band = radius + 1e-6
    for px, py in points:
        lo = np.searchsorted(sorted_x, px - band, side="left")
        hi = np.searchsorted(sorted_x, px + band, side="right")
        idx = order[lo:hi]
        near[idx] |= np.hypot(xs[idx] - px, ys[idx] - py) <= radius
    return near
