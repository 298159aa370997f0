"""Numba kernels of the navfn-like planner: Dijkstra navigation function on the costmap."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_SQRT2 = math.sqrt(2.0)
_DY = np.array([-1, 1, 0, 0, -1, -1, 1, 1], dtype=np.int64)
_DX = np.array([0, 0, -1, 1, -1, 1, -1, 1], dtype=np.int64)
_DL = np.array([1.0, 1.0, 1.0, 1.0, _SQRT2, _SQRT2, _SQRT2, _SQRT2])
NO_PARENT = 255  # `dijkstra`'s parent code of the start cell (the steps are 0-7)


@njit(cache=True, inline="always")
def _cell_cost(inflated, unknown, iy, ix, neutral, factor, allow_unknown, escaping, blocked):
    """navfn's step cost of entering a cell (NavFn::setCostmap); inf when not traversable.

    Costs below `blocked` become neutral + factor * cost; unknown cells cost COST_OBS - 1
    (253) when planning through unknown space is allowed. `blocked` is INSCRIBED in navfn;
    ours may be lower, keeping plans a margin off obstacles (what the local planner's padded
    footprint needs). Blocked cells may be entered only while escaping, near the start: 2
    from a blocked cell (a robot that stands too near a wall must be able to leave; any
    non-lethal cell), 1 from another (a pocket the map closed around the robot must not
    trap the plan; cells below INSCRIBED). Farther away, blocked cells stay blocked: a plan
    must not thread along walls' inscribed zones into their unknown insides.
    """
    c = inflated[iy, ix]
    if c >= 254 or (unknown[iy, ix] and not allow_unknown):
        return math.inf
    if c >= blocked:
        return 253.0 if escaping == 2 or (escaping == 1 and c < 253) else math.inf
    if unknown[iy, ix]:
        return 253.0
    return neutral + factor * c


@njit(cache=True, inline="always")
def _push(keys, vals, n, key, val):
    """Push onto the binary heap (keys, vals)[:n] (room for it is the caller's); new n."""
    i = n
    while i > 0:
        p = (i - 1) >> 1
        if keys[p] <= key:
            break
        keys[i] = keys[p]
        vals[i] = vals[p]
        i = p
    keys[i] = key
    vals[i] = val
    return n + 1


@njit(cache=True, inline="always")
def _pop(keys, vals, n):
    """Pop the least key of the binary heap (keys, vals)[:n]: (key, val, new n)."""
    key = keys[0]
    val = vals[0]
    n -= 1
    last_k = keys[n]
    last_v = vals[n]
    i = 0
    while True:
        a = 2 * i + 1
        if a >= n:
            break
        b = a + 1
        m = b if (b < n and keys[b] < keys[a]) else a
        if last_k <= keys[m]:
            break
        keys[i] = keys[m]
        vals[i] = vals[m]
        i = m
    keys[i] = last_k
    vals[i] = last_v
    return key, val, n


@njit(cache=True, inline="always")
def _octile(iy, ix, gy, gx, step):
    """Octile distance between two cells times the cheapest step cost (admissible)."""
    dy = abs(iy - gy)
    dx = abs(ix - gx)
    return step * (max(dx, dy) + (_SQRT2 - 1.0) * min(dx, dy))


@njit(cache=True)
def dijkstra(
    inflated,
    unknown,
    start_iy,
    start_ix,
    target,
    stop_extra,
    neutral,
    factor,
    allow_unknown,
    potential,
    parent,
    stamp,
    run_id,
    goal_iy=-1,
    goal_ix=-1,
    blocked=253,
    escape_cells=0,
    deep_cells=-1,
):
    """Dijkstra navigation function from the start cell (8-connected), with early exit.

    inflated: (H, W) uint8 costmap values from obstacles; unknown: (H, W) bool; target: (H, W)
    bool cells to reach. The search stops once a target cell is settled and the frontier of the
    search has gone `stop_extra` potential units past it (0: stop at the first). potential
    (H, W) float64, parent (H, W) uint8 and stamp (H, W) int32 are reusable buffers: a cell's
    entries are valid only where stamp == run_id, so no buffer is cleared. parent holds the
    step k (`_DY[k]`, `_DX[k]`) that reached the cell, NO_PARENT at the start: 1 byte a cell
    where a flat index took 4.
    The heap's arrays grow before a cell's neighbours are pushed, not inside `_push`: an
    array handed back from the inlined push on every step cost a third of the search.
    Returns `(K,) int64` flat indices of the target cells settled, nearest first.

    Only from cells within `escape_cells` of the start may blocked cells be entered (at 253 a
    step): the robot stands there, so it can drive out. Cells at or above INSCRIBED (where
    the footprint would touch an obstacle) only within `deep_cells` (-1: escape_cells): a
    wide escape from a pocket may cross gaps under the margin, never chain through the
    inscribed zones of furniture, where the robot does not fit.

    With a goal cell (goal_iy >= 0) the queue is ordered by potential plus the octile
    distance to it times the cheapest step cost (A*): an admissible bound, so the goal's
    potential and path are those Dijkstra finds, after far fewer expansions.
    """
    h, w = inflated.shape
    keys = np.empty(4096, dtype=np.float64)
    vals = np.empty(4096, dtype=np.int64)
    found = np.empty(64, dtype=np.int64)
    n_found = 0
    first = math.inf
    s = start_iy * w + start_ix
    potential[start_iy, start_ix] = 0.0
    parent[start_iy, start_ix] = NO_PARENT
    stamp[start_iy, start_ix] = run_id
    use_h = goal_iy >= 0
    escape2 = escape_cells * escape_cells
    deep2 = escape2 if deep_cells < 0 else deep_cells * deep_cells
    n = _push(keys, vals, 0, 0.0, s)
    while n > 0:
        key, idx, n = _pop(keys, vals, n)
        iy = idx // w
        ix = idx - iy * w
        d = potential[iy, ix]
        if use_h:
            if key > d + _octile(iy, ix, goal_iy, goal_ix, neutral) + 1e-9:
                continue  # stale heap entry
        elif key > d:
            continue  # stale heap entry
        if d > first + stop_extra:
            break
        if target[iy, ix]:
            if n_found == found.shape[0]:
                f2 = np.empty(2 * n_found, dtype=np.int64)
                f2[:n_found] = found
                found = f2
            found[n_found] = idx
            n_found += 1
            if first == math.inf:
                first = d
                if stop_extra <= 0.0:
                    break
        r2 = (iy - start_iy) ** 2 + (ix - start_ix) ** 2
        if r2 > escape2:
            escaping = 0
        elif inflated[iy, ix] >= blocked and r2 <= deep2:
            escaping = 2
        else:
            escaping = 1
        inner = 0 < iy < h - 1 and 0 < ix < w - 1
        if n + 8 > keys.shape[0]:
            k2 = np.empty(2 * keys.shape[0], dtype=keys.dtype)
            v2 = np.empty(2 * keys.shape[0], dtype=vals.dtype)
            k2[:n] = keys[:n]
            v2[:n] = vals[:n]
            keys = k2
            vals = v2
        for k in range(8):
            jy = iy + _DY[k]
            jx = ix + _DX[k]
            if not inner and (jy < 0 or jy >= h or jx < 0 or jx >= w):
                continue
            c = _cell_cost(
                inflated, unknown, jy, jx, neutral, factor, allow_unknown, escaping, blocked
            )
            if c == math.inf:
                continue
            nd = d + c * _DL[k]
            if stamp[jy, jx] != run_id or nd < potential[jy, jx]:
                stamp[jy, jx] = run_id
                potential[jy, jx] = nd
                parent[jy, jx] = k
                hk = nd + _octile(jy, jx, goal_iy, goal_ix, neutral) if use_h else nd
                n = _push(keys, vals, n, hk, jy * w + jx)
    return found[:n_found]


@njit(cache=True)
def sealed_off(
    inflated, unknown, goal_iy, goal_ix, start_iy, start_ix, allow_unknown, blocked,
    escape_cells, budget, stamp, run_id, queue,
):  # fmt: skip
    """True when `dijkstra` from the start provably cannot reach the goal; False when it may.

    Away from the start's escape zone a step may enter a cell only if it is passable (below
    `blocked`, and known unless unknown space is allowed), whatever cell it comes from, so
    passable cells form an undirected graph there. The goal's component in it is flooded
    (8-connected); if it has at most `budget` cells and none within escape_cells + 3 of the
    start, no path from the start can enter it: the cell a path comes from into the
    component is either passable (then it would be in the component) or was itself entered
    by escaping, next to the zone. A goal that is not passable, far from the start, cannot be
    entered at all. Costs O(component) instead of Dijkstra's O(everything reachable).
    stamp: reusable (H, W) marks, valid where == run_id; queue: (>= budget,) int64.
    """
    h, w = inflated.shape
    near = (escape_cells + 3) ** 2

    def passable(iy, ix):
        return inflated[iy, ix] < blocked and (allow_unknown or not unknown[iy, ix])

    if (goal_iy - start_iy) ** 2 + (goal_ix - start_ix) ** 2 <= near:
        return False
    if not passable(goal_iy, goal_ix):
        return True
    stamp[goal_iy, goal_ix] = run_id
    queue[0] = goal_iy * w + goal_ix
    head, tail = 0, 1
    while head < tail:
        idx = queue[head]
        head += 1
        iy = idx // w
        ix = idx - iy * w
        for k in range(8):
            jy = iy + _DY[k]
            jx = ix + _DX[k]
            if jy < 0 or jy >= h or jx < 0 or jx >= w or stamp[jy, jx] == run_id:
                continue
            if not passable(jy, jx):
                continue
            if (jy - start_iy) ** 2 + (jx - start_ix) ** 2 <= near or tail == budget:
                return False  # may join the start's side, or too big to settle here
            stamp[jy, jx] = run_id
            queue[tail] = jy * w + jx
            tail += 1
    return True


@njit(cache=True)
def trace_path(parent, goal_idx, width):
    """Cells `(K, 2) int64 [iy, ix]` from the start to `goal_idx` by following the steps in
    `parent` (as `dijkstra` writes them) back to the start."""
    n = 1
    iy = goal_idx // width
    ix = goal_idx - iy * width
    while parent[iy, ix] != NO_PARENT and n <= parent.size:
        k = parent[iy, ix]
        iy -= _DY[k]
        ix -= _DX[k]
        n += 1
    out = np.empty((n, 2), dtype=np.int64)
    iy = goal_idx // width
    ix = goal_idx - iy * width
    for i in range(n - 1, -1, -1):
        out[i, 0] = iy
        out[i, 1] = ix
        if i > 0:
            k = parent[iy, ix]
            iy -= _DY[k]
            ix -= _DX[k]
    return out
