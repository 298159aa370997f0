"""Numba kernels of GMapping's scan matcher: score, likelihood, hill-climbing optimisation.

A beam end point is matched against the occupied cells in a (2k+1)^2 window around it (k =
kernelSize); a cell counts only if occupied (hits / visits > 0.1) while the cell one diagonal
step back towards the robot is not, which keeps a beam from matching the far side of a wall.
The distance mu from the end point to the mean of the hits in the best such cell gives
  score      s = sum over beams of exp(-mu^2 / sigma)
  likelihood l = sum over beams of -mu^2 / lsigma, or -0.5 / lsigma when nothing matched
(GMapping ScanMatcher::score and ::likelihoodAndScore, with its fullness threshold 0.1, read
from the OCCUPIED / FULL bit masks the map keeps).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from worker.slam.map_kernels import ACC_X, ACC_Y, FULL, HITS, OCCUPIED, PATCH_BITS, PATCH_MASK

NULL_LIKELIHOOD = -0.5  # GMapping's nullLikelihood: a beam with no match


@njit(cache=True, inline="always")
def _patch(table, tpx0, tpy0, gx, gy):
    """Pool id of the patch holding cell (gx, gy), -1 when unknown."""
    tx = (gx >> PATCH_BITS) - tpx0
    ty = (gy >> PATCH_BITS) - tpy0
    if tx < 0 or ty < 0 or ty >= table.shape[0] or tx >= table.shape[1]:
        return -1
    return table[ty, tx]


@njit(cache=True)
def score_and_likelihood(
    pool,
    bits,
    table,
    tpx0,
    tpy0,
    x,
    y,
    theta,
    ranges,
    cos_a,
    sin_a,
    res,
    usable_range,
    max_range,
    lskip,
    kernel,
    sigma,
    lsigma,
    want_l,
):
    """(score, log-likelihood) of the scan at pose (x, y, theta) in one particle's map.

    Every (lskip + 1)-th beam is used, from beam lskip; beams beyond usable_range or
    max_range (no return) are left out. want_l = False skips the likelihood (it is then 0).
    One flat loop (no helper calls): this is the innermost loop of the whole filter. Indices
    are cast to unsigned after their bounds checks, which spares numba's wraparound code.
    """
    c = math.cos(theta)
    s = math.sin(theta)
    free_delta = res * math.sqrt(2.0)  # GMapping: one cell diagonal back towards the laser
    inv_res = 1.0 / res
    no_hit = NULL_LIKELIHOOD / lsigma
    th, tw = table.shape
    score = 0.0
    like = 0.0
    for i in range(lskip, ranges.shape[0], lskip + 1):
        r = ranges[i]
        if not r > 0.0 or r > usable_range or r > max_range:
            continue
        ca = c * cos_a[i] - s * sin_a[i]
        sa = s * cos_a[i] + c * sin_a[i]
        hx = x + r * ca
        hy = y + r * sa
        ihx = int(math.floor(hx * inv_res))
        ihy = int(math.floor(hy * inv_res))
        ofx = int(math.floor((hx - free_delta * ca) * inv_res)) - ihx
        ofy = int(math.floor((hy - free_delta * sa) * inv_res)) - ihy
        best = -1.0
        for gy in range(ihy - kernel, ihy + kernel + 1):
            ty = (gy >> PATCH_BITS) - tpy0
            if ty < 0 or ty >= th:
                continue
            ly = np.uintp(gy & PATCH_MASK)
            uty = np.uintp(ty)
            last_tx = -1
            row = np.int64(0)
            e = -1
            for gx in range(ihx - kernel, ihx + kernel + 1):
                tx = (gx >> PATCH_BITS) - tpx0
                if tx != last_tx:  # the window's row crosses at most one patch border
                    last_tx = tx
                    e = table[uty, np.uintp(tx)] if 0 <= tx < tw else -1
                    row = bits[np.uintp(e), OCCUPIED, ly] if e >= 0 else np.int64(0)
                lx = np.uintp(gx & PATCH_MASK)
                if not (row >> lx) & 1:
                    continue
                # the cell before must not be full: the near side of an obstacle only
                gfx = gx + ofx
                gfy = gy + ofy
                tfx = (gfx >> PATCH_BITS) - tpx0
                tfy = (gfy >> PATCH_BITS) - tpy0
                if 0 <= tfx < tw and 0 <= tfy < th:
                    ef = table[np.uintp(tfy), np.uintp(tfx)]
                    if ef >= 0:
                        row_f = bits[np.uintp(ef), FULL, np.uintp(gfy & PATCH_MASK)]
                        if (row_f >> np.uintp(gfx & PATCH_MASK)) & 1:
                            continue
                ue = np.uintp(e)
                hits = pool[ue, ly, lx, HITS]
                mx = gx * res + pool[ue, ly, lx, ACC_X] / hits
                my = gy * res + pool[ue, ly, lx, ACC_Y] / hits
                d2 = (hx - mx) * (hx - mx) + (hy - my) * (hy - my)
                if best < 0 or d2 < best:
                    best = d2
        if best >= 0:
            score += math.exp(-best / sigma)
            if want_l:
                like -= best / lsigma
        elif want_l:
            like += no_hit
    return score, like


@njit(cache=True)
def optimize(
    pool,
    bits,
    table,
    tpx0,
    tpy0,
    pose,
    ranges,
    cos_a,
    sin_a,
    res,
    usable_range,
    max_range,
    lskip,
    kernel,
    sigma,
    lstep,
    astep,
    iterations,
):
    """Hill climbing from pose (GMapping ScanMatcher::optimize); returns (pose (3,), score).

    Tries steps of +-ldelta in x and y (map frame) and +-adelta in theta, moves to the best
    one while it improves the score, and halves both steps when none does, `iterations` times.
    The step straight back to where the last move came from is not scored again: that pose
    scored lower than the current one, so it can never be chosen (a pure saving).
    """
    best_pose = pose.copy()
    cur, _ = score_and_likelihood(
        pool,
        bits,
        table,
        tpx0,
        tpy0,
        pose[0],
        pose[1],
        pose[2],
        ranges,
        cos_a,
        sin_a,
        res,
        usable_range,
        max_range,
        lskip,
        kernel,
        sigma,
        1.0,
        False,
    )
    ldelta = lstep
    adelta = astep
    refinement = 0
    best = -1.0
    came_by = -1  # the move that led to the current pose at the current step size
    while True:
        if best >= cur:
            refinement += 1
            ldelta *= 0.5
            adelta *= 0.5
            came_by = -1
        best = cur
        bx, by, bt = best_pose[0], best_pose[1], best_pose[2]
        nx, ny, nt = bx, by, bt
        chosen = -1
        for move in range(6):
            if came_by >= 0 and move == came_by ^ 1:  # moves 0/1, 2/3, 4/5 undo each other
                continue
            x, y, t = bx, by, bt
            if move == 0:
                x += ldelta
            elif move == 1:
                x -= ldelta
            elif move == 2:
                y -= ldelta
            elif move == 3:
                y += ldelta
            elif move == 4:
                t += adelta
            else:
                t -= adelta
            sc, _ = score_and_likelihood(
                pool,
                bits,
                table,
                tpx0,
                tpy0,
                x,
                y,
                t,
                ranges,
                cos_a,
                sin_a,
                res,
                usable_range,
                max_range,
                lskip,
                kernel,
                sigma,
                1.0,
                False,
            )
            if sc > cur:
                cur = sc
                nx, ny, nt = x, y, t
                chosen = move
        best_pose[0], best_pose[1], best_pose[2] = nx, ny, nt
        came_by = chosen
        if not (cur > best or refinement < iterations):
            break
    best_pose[2] = (best_pose[2] + math.pi) % (2 * math.pi) - math.pi
    return best_pose, cur


# layout of the `cfg` array the drivers take (one float64 array instead of eleven arguments)
CFG_FIELDS = (
    "res",
    "usable_range",
    "max_range",
    "lskip",
    "kernel",
    "sigma",
    "lsigma",
    "lstep",
    "astep",
    "iterations",
    "minimum_score",
)


@njit(cache=True)
def _match_particle(
    p, out, scores, likes, pool, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg
):
    """Improved proposal of particle p: write its pose, score and log-likelihood at [p]."""
    res, usable, max_range = cfg[0], cfg[1], cfg[2]
    lskip, kernel = int(cfg[3]), int(cfg[4])
    sigma, lsigma, lstep, astep = cfg[5], cfg[6], cfg[7], cfg[8]
    iterations, minimum_score = int(cfg[9]), cfg[10]
    table = tables[p]
    refined, sc = optimize(
        pool,
        bits,
        table,
        tpx0,
        tpy0,
        poses[p],
        ranges,
        cos_a,
        sin_a,
        res,
        usable,
        max_range,
        lskip,
        kernel,
        sigma,
        lstep,
        astep,
        iterations,
    )
    if sc > minimum_score:
        out[p] = refined
    else:
        out[p] = poses[p]
    _, like = score_and_likelihood(
        pool,
        bits,
        table,
        tpx0,
        tpy0,
        out[p, 0],
        out[p, 1],
        out[p, 2],
        ranges,
        cos_a,
        sin_a,
        res,
        usable,
        max_range,
        lskip,
        kernel,
        sigma,
        lsigma,
        True,
    )
    scores[p] = sc
    likes[p] = like


@njit(cache=True)
def scan_match_all(pool, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg):
    """The improved proposal for every particle (GMapping GridSlamProcessor::scanMatch).

    Each particle's pose is refined against its own map, kept as drawn from the motion model
    when the match score is not above minimum_score. Returns (poses (N, 3), score (N,),
    log-likelihood (N,)) with the likelihood at the final pose. cfg: see CFG_FIELDS.
    """
    n = poses.shape[0]
    out = np.empty_like(poses)
    scores = np.zeros(n)
    likes = np.zeros(n)
    for p in range(n):
        _match_particle(
            p, out, scores, likes, pool, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg
        )
    return out, scores, likes


@njit(cache=True, parallel=True)
def scan_match_all_parallel(pool, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg):
    """scan_match_all with the particles spread over numba's threads; the same result (each
    particle reads the shared maps and writes only its own row)."""
    n = poses.shape[0]
    out = np.empty_like(poses)
    scores = np.zeros(n)
    likes = np.zeros(n)
    for p in prange(n):
        _match_particle(
            p, out, scores, likes, pool, bits, tables, tpx0, tpy0, poses, ranges, cos_a, sin_a, cfg
        )
    return out, scores, likes
