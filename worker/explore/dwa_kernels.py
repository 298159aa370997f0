"""Numba kernels of the DWA local planner: distance maps, trajectory roll-out and scoring."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from worker.explore.costmap_kernels import footprint_collides

# Indices into the float64 parameter vector the kernel takes (numba has no dataclasses).
P_DT = 0  # [s] control period: the dynamic window is what acc limits reach in one period
P_MAX_VX = 1
P_MIN_VX = 2
P_MAX_VTH = 3
P_MIN_INPLACE_VTH = 4
P_ACC_X = 5
P_ACC_TH = 6
P_SIM_TIME = 7
P_SIM_GRAN = 8
P_ANG_GRAN = 9
P_PDIST = 10
P_GDIST = 11
P_OCCDIST = 12
P_LOOKAHEAD = 13
P_HALF = 14  # [m] half side of the footprint
P_CIRC = 15  # [m] circumscribed radius
P_ESCAPE_VX = 16
P_HALF_RAW = 17  # [m] half side without padding
N_PARAMS = 18


@njit(cache=True)
def wavefront(seeds, cost, resolution):
    """4-connected breadth-first distance [m] from seed cells through cells below INSCRIBED.

    seeds: (K, 2) int64 [iy, ix] (seeded even when they lie in an obstacle); cost: (n, n) uint8.
    Returns (n, n) float32, inf where unreachable: base_local_planner's MapGrid distances with
    meter_scoring.
    """
    h, w = cost.shape
    dist = np.empty((h, w), dtype=np.float32)
    wavefront_into(seeds, cost, resolution, dist, np.empty(h * w, dtype=np.int64))
    return dist


@njit(cache=True)
def wavefront_into(seeds, cost, resolution, dist, queue, cy=0, cx=0, r=-1):
    """`wavefront` written into `dist (n, n) float32`, with `queue (n * n,) int64` as its
    work space (both reused from call to call: no allocation at 10 Hz).

    With r >= 0 only the square of cells within r (rows and columns) of cell (cy, cx) is
    asked for: the search stops once every cell there below INSCRIBED has its distance
    (a cell's first visit is final), so those cells hold what the whole search gives them;
    cells outside it may be left at inf. A square cell that cannot be reached keeps the
    search going to its end, as without r."""
    h, w = cost.shape
    dist[:, :] = np.inf
    y0 = 0 if r < 0 else max(0, cy - r)
    y1 = h - 1 if r < 0 else min(h - 1, cy + r)
    x0 = 0 if r < 0 else max(0, cx - r)
    x1 = w - 1 if r < 0 else min(w - 1, cx + r)
    need = 0  # the square's traversable cells not reached yet (0 and r < 0: never stops)
    if r >= 0:
        for iy in range(y0, y1 + 1):
            for ix in range(x0, x1 + 1):
                if cost[iy, ix] < 253:
                    need += 1
    head = 0
    tail = 0
    for i in range(seeds.shape[0]):
        iy = seeds[i, 0]
        ix = seeds[i, 1]
        if 0 <= iy < h and 0 <= ix < w and dist[iy, ix] == np.inf:
            dist[iy, ix] = 0.0
            queue[tail] = iy * w + ix
            tail += 1
            if y0 <= iy <= y1 and x0 <= ix <= x1 and cost[iy, ix] < 253:
                need -= 1
    if r >= 0 and need == 0:
        return
    while head < tail:
        idx = queue[head]
        head += 1
        iy = idx // w
        ix = idx - iy * w
        nd = dist[iy, ix] + resolution
        for k in range(4):
            jy = iy + (1 if k == 0 else (-1 if k == 1 else 0))
            jx = ix + (1 if k == 2 else (-1 if k == 3 else 0))
            if jy < 0 or jy >= h or jx < 0 or jx >= w:
                continue
            if cost[jy, jx] >= 253 or dist[jy, jx] != np.inf:  # BFS: first visit is final
                continue
            dist[jy, jx] = nd
            queue[tail] = jy * w + jx
            tail += 1
            if r >= 0 and y0 <= jy <= y1 and x0 <= jx <= x1:
                need -= 1
                if need == 0:
                    return


@njit(cache=True)
def score_trajectory(
    x, y, th, vx, vth, lethal, near, inner, cost, path_dist, goal_dist, ox, oy, res, prm,
    half=-1.0, bound=np.inf,
):  # fmt: skip
    """Roll out constant (vx, vth) for sim_time and score it; negative when illegal.

    -1: the footprint hits an obstacle cell of the local costmap at some step; -2: a point has
    no path or goal distance (off the window, or cut off by obstacles). Otherwise the score of
    the end point, base_local_planner's (thesis eq. 5.1):
    pdist * path_dist + gdist * goal_dist + occdist * max centre cost along the trajectory
    (the caller folds meter_scoring into the weights). bound: a trajectory whose score would
    be `>= bound` cannot win, so its footprint is not tested (the costly part): -3.
    """
    h, w = lethal.shape
    if half < 0.0:
        half = prm[P_HALF]
    dist_lin = abs(vx) * prm[P_SIM_TIME]
    dist_ang = abs(vth) * prm[P_SIM_TIME]
    n = int(max(dist_lin / prm[P_SIM_GRAN], dist_ang / prm[P_ANG_GRAN]) + 0.5)
    n = max(n, 1)
    dt = prm[P_SIM_TIME] / n
    # pass 1: the score from the centre's cells alone (cheap)
    occ = 0.0
    pd = 0.0
    gd = 0.0
    px = x
    py = y
    pth = th
    for _ in range(n):
        px += vx * math.cos(pth) * dt
        py += vx * math.sin(pth) * dt
        pth += vth * dt
        ix = int(math.floor((px - ox) / res))
        iy = int(math.floor((py - oy) / res))
        if ix < 0 or ix >= w or iy < 0 or iy >= h:
            return -2.0
        c = float(cost[iy, ix])
        if c > occ:
            occ = c
        pd = path_dist[iy, ix]
        gd = goal_dist[iy, ix]
        if pd == np.inf or gd == np.inf:
            return -2.0
    score = prm[P_PDIST] * pd + prm[P_GDIST] * gd + prm[P_OCCDIST] * occ
    if score >= bound:
        return -3.0
    # pass 2: the footprint at every step, on the same sample points
    for _ in range(n):
        x += vx * math.cos(th) * dt
        y += vx * math.sin(th) * dt
        th += vth * dt
        if footprint_collides(lethal, near, inner, ox, oy, res, x, y, th, half):
            return -1.0
    return score


@njit(cache=True)
def lookahead_goal_dist(x, y, th, vth, goal_dist, ox, oy, res, prm):
    """Goal distance heading_lookahead ahead of where an in-place rotation ends (inf: off map)."""
    th_end = th + vth * prm[P_SIM_TIME]
    px = x + prm[P_LOOKAHEAD] * math.cos(th_end)
    py = y + prm[P_LOOKAHEAD] * math.sin(th_end)
    h, w = goal_dist.shape
    ix = int(math.floor((px - ox) / res))
    iy = int(math.floor((py - oy) / res))
    if ix < 0 or ix >= w or iy < 0 or iy >= h:
        return np.inf
    return goal_dist[iy, ix]


@njit(cache=True)
def best_command(
    x, y, th, v0, w0, goal_gap, stuck_left, stuck_right, escaping, n_vx, n_vth,
    lethal, near, inner, cost, path_dist, goal_dist, ox, oy, res, prm, allow_escape=True,
):  # fmt: skip
    """Dynamic Window Approach as base_local_planner's TrajectoryPlanner (dwa: true) does it.

    Forward samples: n_vx x n_vth velocities reachable within one control period, the top
    speed capped by goal_gap / sim_time so the robot slows down at its goal. In-place
    rotations (at least min_in_place_vel) replace the best forward trajectory when they score
    no worse, preferring the one that looks most towards the goal, and not a direction flagged
    as oscillating. If nothing is legal, back off at escape_vel; while `escaping` (after a
    back-off, until the robot got clear) no forward samples. Returns (vx, vth, score, kind):
    kind 0 forward, 1 rotation, 2 escape, -1 nothing legal.
    """
    dt = prm[P_DT]
    top = min(prm[P_MAX_VX], goal_gap / prm[P_SIM_TIME])
    vx_hi = max(min(top, v0 + prm[P_ACC_X] * dt), prm[P_MIN_VX])
    vx_lo = max(prm[P_MIN_VX], v0 - prm[P_ACC_X] * dt)
    if vx_hi < vx_lo:
        vx_hi = vx_lo
    vth_lo = max(-prm[P_MAX_VTH], w0 - prm[P_ACC_TH] * dt)
    vth_hi = min(prm[P_MAX_VTH], w0 + prm[P_ACC_TH] * dt)
    dvth = (vth_hi - vth_lo) / max(n_vth - 1, 1)
    best = -1.0
    bvx = 0.0
    bvth = 0.0
    kind = -1
    # Keeping the current velocities is a sample too: the trajectory chosen a period ago
    # stays available (the grid of samples alone need not contain it).
    vk = min(max(v0, vx_lo), vx_hi)
    wk = min(max(w0, vth_lo), vth_hi)
    s = -1.0
    if not escaping:
        s = score_trajectory(
            x, y, th, vk, wk, lethal, near, inner, cost, path_dist, goal_dist, ox, oy, res, prm
        )
    if s >= 0.0:
        best, bvx, bvth, kind = s, vk, wk, 0
    # Fastest first and straight ahead first: on the grid many samples score the same and the
    # first of equal scores wins (ROS starts from the slowest; we prefer progress).
    for i in range(n_vx - 1, -1, -1):
        if escaping:
            break
        vx = vx_lo if n_vx == 1 else vx_lo + (vx_hi - vx_lo) * i / (n_vx - 1)
        for j in range(-1, n_vth):
            vth = 0.0 if j < 0 else vth_lo + dvth * j
            s = score_trajectory(
                x, y, th, vx, vth, lethal, near, inner, cost, path_dist, goal_dist, ox, oy, res,
                prm, -1.0, best if best >= 0.0 else np.inf,
            )  # fmt: skip
            if s >= 0.0 and (best < 0.0 or s < best):
                best, bvx, bvth, kind = s, vx, vth, 0
    heading_dist = np.inf
    for j in range(n_vth):
        vth = vth_lo + dvth * j
        if abs(vth) <= dvth:
            continue  # (almost) no rotation: nothing to gain in place
        if (vth > 0.0 and stuck_left) or (vth < 0.0 and stuck_right):
            continue
        vlim = max(vth, prm[P_MIN_INPLACE_VTH]) if vth > 0 else min(vth, -prm[P_MIN_INPLACE_VTH])
        # rotations tie with the best (score <= best): bound just above it
        s = score_trajectory(
            x, y, th, 0.0, vlim, lethal, near, inner, cost, path_dist, goal_dist, ox, oy, res,
            prm, -1.0, best + 1e-9 * (1.0 + best) if best >= 0.0 else np.inf,
        )  # fmt: skip
        if s >= 0.0 and (best < 0.0 or s <= best):
            ahead = lookahead_goal_dist(x, y, th, vlim, goal_dist, ox, oy, res, prm)
            # the first legal rotation is taken even when it looks at no reachable cell (inf),
            # as TrajectoryPlanner's DBL_MAX start does: otherwise a robot among obstacles
            # could never turn on the spot
            if kind != 1 or ahead < heading_dist:
                heading_dist = ahead
                best, bvx, bvth, kind = s, 0.0, vlim, 1
    if kind < 0 and allow_escape:
        # base_local_planner backs off even when the padded footprint is already touching;
        # we back off when the unpadded one stays clear.
        s = score_trajectory(
            x, y, th, prm[P_ESCAPE_VX], 0.0, lethal, near, inner, cost, path_dist, goal_dist,
            ox, oy, res, prm, prm[P_HALF_RAW],
        )  # fmt: skip
        if s >= 0.0:
            best, bvx, bvth, kind = s, prm[P_ESCAPE_VX], 0.0, 2
    return bvx, bvth, best, kind


@njit(cache=True)
def rotation_legal(x, y, th, vth, lethal, near, inner, ox, oy, res, prm):
    """True when rotating in place at vth for sim_time keeps the footprint clear."""
    n = max(1, int(abs(vth) * prm[P_SIM_TIME] / prm[P_ANG_GRAN] + 0.5))
    dt = prm[P_SIM_TIME] / n
    for _ in range(n):
        th += vth * dt
        if footprint_collides(lethal, near, inner, ox, oy, res, x, y, th, prm[P_HALF]):
            return False
    return True


@njit(cache=True)
def motion_legal(x, y, th, v, w, duration, lethal, near, inner, ox, oy, res, half, step):
    """True when driving (v, w) for `duration` [s] keeps the footprint clear (sampled every
    `step` [m] or rad of motion)."""
    n = max(1, int(max(abs(v), abs(w)) * duration / step + 0.5))
    dt = duration / n
    for _ in range(n):
        x += v * math.cos(th) * dt
        y += v * math.sin(th) * dt
        th += w * dt
        if footprint_collides(lethal, near, inner, ox, oy, res, x, y, th, half):
            return False
    return True
