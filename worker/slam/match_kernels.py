"""Numba kernels of GMapping's scan matcher: score, likelihood, hill-climbing optimisation.

A beam end point is matched against the occupied cells in a (2k+1)^2 window around it (k =
kernelSize); a cell counts only if occupied (hits / visits > 0.1) while the cell one diagonal
step back towards the robot is not, which keeps a beam from matching the far side of a wall.
The distance mu from the end point to the mean of the hits in the best such cell gives
  score      s = sum over beams of exp(-mu^2 / sigma)
  likelihood l = sum over beams of -mu^2 / lsigma, or -0.5 / lsigma when nothing matched
(GMapping ScanMatcher::score and ::likelihoodAndScore, with its fullness threshold 0.1, read
from the OCCUPIED / FULL bit masks the map keeps).

Speed, with the same score: the used beams' end and free points are computed once per update
in the robot frame (`prepare_beams`); a window row is read as one bit mask; and a candidate
pose of the hill climbing stops being scored as soon as it can no longer beat the current
pose (each beam adds at most 1), with the beams taken worst-matched first (their order at the
particle's initial pose), so that a losing candidate falls behind early; that test runs on an
upper bound of exp (a polynomial), and the exponentials are taken only for a pose that may
win (about a quarter of the beams scored; exp had been a sixth of the matcher's time); each
beam's matching cells (their hit means, after the occupancy and free-cell tests) are remembered for
the current pose of the climb, keyed by the end-point cell and free-cell offset: a candidate
whose end point stays in the same cell (about half of them) reuses them.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from worker.slam.map_kernels import FULL, OCCUPIED, PATCH, PATCH_BITS, PATCH_MASK
from worker.slam.match_cache_kernels import MAX_CACHED_KERNEL, commit_cache, new_cache

NULL_LIKELIHOOD = -0.5  # GMapping's nullLikelihood: a beam with no match
FREE_CELL_RATIO = math.sqrt(2.0)  # GMapping's freeCellRatio: free point this many cells back
MAX_KERNEL = 15  # [cells] a window row must fit in two patches
_SLACK = 1e-6  # abort margin: far above the rounding of a sum of <= 1e5 terms <= 1

# layout of the `cfg` array the kernels take (one float64 array instead of eleven arguments)
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
    "coarse_skip",
    "coarse_levels",
)
C_RES, C_USABLE, C_MAX, C_LSKIP, C_KERNEL, C_SIGMA, C_LSIGMA = 0, 1, 2, 3, 4, 5, 6
C_LSTEP, C_ASTEP, C_ITERATIONS, C_MINIMUM_SCORE = 7, 8, 9, 10
C_COARSE_SKIP, C_COARSE_LEVELS = 11, 12
# fields match_config fills in when left out: coarse-to-fine climbing off (GMapping's climb)
_OPTIONAL = {"coarse_skip": 0, "coarse_levels": 0}


def match_config(**fields: float) -> np.ndarray:
    """The cfg array from keyword values named as CFG_FIELDS (all required but coarse_skip
    and coarse_levels, 0 when left out)."""
    fields = {**_OPTIONAL, **fields}
    missing = set(CFG_FIELDS) - set(fields)
    if missing or len(fields) != len(CFG_FIELDS):
        raise ValueError(f"match_config needs exactly {CFG_FIELDS}; missing {sorted(missing)}")
    if not 0 <= fields["kernel"] <= MAX_KERNEL:
        raise ValueError(f"kernel must be in [0, {MAX_KERNEL}] cells, got {fields['kernel']}")
    if fields["coarse_skip"] < 0 or not 0 <= fields["coarse_levels"] <= fields["iterations"]:
        raise ValueError(
            "coarse_skip must be >= 0 and coarse_levels in [0, iterations], got "
            f"{fields['coarse_skip']} and {fields['coarse_levels']}"
        )
    return np.array([fields[k] for k in CFG_FIELDS], dtype=np.float64)


@intrinsic
def _ctz(typingctx, x):
    """Index of the lowest set bit of a non-zero int64 (LLVM's cttz: one instruction)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        i64 = ir.IntType(64)
        fnty = ir.FunctionType(i64, [i64, ir.IntType(1)])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.cttz.i64")
        return builder.call(fn, [args[0], ir.Constant(ir.IntType(1), 1)])

    return sig, codegen


@njit(cache=True, nogil=True, inline="always")
def exp_neg_upper(x):
    """An upper bound of exp(-x) for x >= 0, without exp: the Taylor polynomial to x^2 below
    1 (the series alternates), 1 / (1 + x) above (e^x >= 1 + x)."""
    return 1.0 - x + 0.5 * x * x if x < 1.0 else 1.0 / (1.0 + x)


@njit(cache=True, nogil=True)
def prepare_beams(ranges, cos_a, sin_a, cfg):
    """(M, 4) [hx, hy, fx, fy] robot frame [m]: end point and free point of each used beam.

    Every (lskip + 1)-th beam is used, from beam lskip (GMapping's likelihoodSkip); beams
    beyond usable_range or max_range (no return), 0 or NaN are left out. The free point lies
    FREE_CELL_RATIO cells back along the beam.
    """
    res, usable, max_range = cfg[C_RES], cfg[C_USABLE], cfg[C_MAX]
    lskip = int(cfg[C_LSKIP])
    back = res * FREE_CELL_RATIO
    out = np.empty((ranges.shape[0], 4))
    m = 0
    for i in range(lskip, ranges.shape[0], lskip + 1):
        r = ranges[i]
        if not r > 0.0 or r > usable or r > max_range:
            continue
        out[m, 0] = r * cos_a[i]
        out[m, 1] = r * sin_a[i]
        out[m, 2] = (r - back) * cos_a[i]
        out[m, 3] = (r - back) * sin_a[i]
        m += 1
    return out[:m].copy()


@njit(cache=True, nogil=True)
def _score(
    mean, bits, table, tpx0, tpy0, x, y, theta, beams, order, cfg, bound, terms, dist2, cache, w
):
    """(score, log-likelihood, complete) of the beams at pose (x, y, theta), in `order`.

    Stops (complete = False; the bound and likelihood summed so far) as soon as the score can
    no longer exceed `bound`, judged on an upper bound of each beam's term (exp_neg_upper):
    the exponentials are taken, after the loop, only for a pose that may beat `bound`, in
    the same order, so the score is the same to the last bit.
    terms: (M,) gets each beam's score term when complete (pass an empty array to skip).
    dist2: (M,) scratch for each beam's squared distance (inf: no match).
    cache: see new_cache; a beam whose key matches the committed entry reuses its points,
    the others are scored on the map and recorded in scratch slot w. One flat loop (no
    calls): this is the innermost loop of the whole filter.
    """
    res, kernel, sigma, lsigma = cfg[C_RES], int(cfg[C_KERNEL]), cfg[C_SIGMA], cfg[C_LSIGMA]
    inv_res = 1.0 / res
    inv_sigma = 1.0 / sigma  # the bound only; the terms divide as GMapping does
    no_hit = NULL_LIKELIHOOD / lsigma
    nb = 2 * kernel + 1
    wmask = (np.int64(1) << nb) - 1
    c = math.cos(theta)
    s = math.sin(theta)
    th, tw = table.shape
    n = order.shape[0]
    keep = terms.shape[0] == n
    ckey, cn, cpts, skey, sn, spts, smiss, snmiss = cache
    use = cpts.shape[1] > 0
    snmiss[w] = 0
    upper = 0.0
    like = 0.0
    for k in range(n):
        if upper + (n - k) + _SLACK < bound:
            return upper, like, False
        i = order[k]
        hx = x + c * beams[i, 0] - s * beams[i, 1]
        hy = y + s * beams[i, 0] + c * beams[i, 1]
        ihx = int(math.floor(hx * inv_res))
        ihy = int(math.floor(hy * inv_res))
        ofx = int(math.floor((x + c * beams[i, 2] - s * beams[i, 3]) * inv_res)) - ihx
        ofy = int(math.floor((y + s * beams[i, 2] + c * beams[i, 3]) * inv_res)) - ihy
        key = ((ihx + 0x800000) << 40) | ((ihy + 0x800000) << 16) | ((ofx + 8) << 8) | (ofy + 8)
        if use and key == ckey[i]:
            best = np.inf
            for q in range(cn[i]):
                mx = hx - cpts[i, q, 0]
                my = hy - cpts[i, q, 1]
                d2 = mx * mx + my * my
                if d2 < best:
                    best = d2
        else:
            npts = 0
            # the window's rows as bit masks (bit j = cell gx0 + j); a row spans at most two
            # patches, and so does the row of free cells one step back along the beam
            gx0 = ihx - kernel
            tx0 = (gx0 >> PATCH_BITS) - tpx0
            lx0 = gx0 & PATCH_MASK
            in0 = 0 <= tx0 < tw
            in1 = lx0 + nb > PATCH and 0 <= tx0 + 1 < tw
            gf0 = gx0 + ofx
            tf0 = (gf0 >> PATCH_BITS) - tpx0
            lf0 = gf0 & PATCH_MASK
            inf0 = 0 <= tf0 < tw
            inf1 = lf0 + nb > PATCH and 0 <= tf0 + 1 < tw
            best = np.inf
            for gy in range(ihy - kernel, ihy + kernel + 1):
                ty = (gy >> PATCH_BITS) - tpy0
                if ty < 0 or ty >= th:
                    continue
                uty = np.uintp(ty)
                ly = np.uintp(gy & PATCH_MASK)
                e0 = table[uty, np.uintp(tx0)] if in0 else -1
                e1 = table[uty, np.uintp(tx0 + 1)] if in1 else -1
                occ = bits[np.uintp(e0), OCCUPIED, ly] >> lx0 if e0 >= 0 else np.int64(0)
                if e1 >= 0:
                    occ |= bits[np.uintp(e1), OCCUPIED, ly] << (PATCH - lx0)
                occ &= wmask
                if occ == 0:
                    continue
                # the cell one step back along the beam must not be full (near side of a wall)
                gfy = gy + ofy
                tfy = (gfy >> PATCH_BITS) - tpy0
                if 0 <= tfy < th:
                    utf = np.uintp(tfy)
                    lfy = np.uintp(gfy & PATCH_MASK)
                    f0 = table[utf, np.uintp(tf0)] if inf0 else -1
                    f1 = table[utf, np.uintp(tf0 + 1)] if inf1 else -1
                    if f0 >= 0:
                        occ &= ~(bits[np.uintp(f0), FULL, lfy] >> lf0)
                    if f1 >= 0:
                        occ &= ~(bits[np.uintp(f1), FULL, lfy] << (PATCH - lf0))
                while occ != 0:  # the set bits, lowest first
                    j = _ctz(occ)
                    occ &= occ - 1
                    gx = gx0 + j
                    e = np.uintp(e0 if lx0 + j < PATCH else e1)
                    lx = np.uintp(gx & PATCH_MASK)
                    px = gx * res + mean[e, ly, lx, 0]
                    py = gy * res + mean[e, ly, lx, 1]
                    if use:
                        spts[w, i, npts, 0] = px
                        spts[w, i, npts, 1] = py
                        npts += 1
                    mx = hx - px
                    my = hy - py
                    best = min(best, mx * mx + my * my)
            if use:
                skey[w, i] = key
                sn[w, i] = npts
                smiss[w, snmiss[w]] = i
                snmiss[w] += 1
        if best < np.inf:
            upper += exp_neg_upper(best * inv_sigma)
            like -= best / lsigma
        else:
            like += no_hit
        dist2[k] = best
    if upper + _SLACK < bound:
        return upper, like, False
    score = 0.0
    for k in range(n):
        term = math.exp(-dist2[k] / sigma) if dist2[k] < np.inf else 0.0
        score += term
        if keep:
            terms[order[k]] = term
    return score, like, True


@njit(cache=True, nogil=True)
def score_and_likelihood(mean, bits, table, tpx0, tpy0, pose, beams, cfg):
    """(score, log-likelihood) of the prepared beams at pose (3,) in one particle's map."""
    order = np.arange(beams.shape[0])
    sc, like, _ = _score(
        mean, bits, table, tpx0, tpy0, pose[0], pose[1], pose[2], beams, order, cfg, -np.inf,
        np.empty(0), np.empty(beams.shape[0]), new_cache(0, MAX_CACHED_KERNEL + 1), 0,
    )  # fmt: skip
    return sc, like


@njit(cache=True, nogil=True)
def _climb(mean, bits, table, tpx0, tpy0, beams, order, cfg, cache, dist2, state):
    """GMapping's hill climbing on `beams` (scored in `order`) from state = [x, y, theta,
    score, like, ldelta, adelta, refinement, last level], in place: the climb ends after a
    round without improvement at refinement `last level` (GMapping: iterations). The cache
    holds the current pose's cells (committed)."""
    bx, by, bt, cur, cur_like = state[0], state[1], state[2], state[3], state[4]
    ldelta, adelta, refinement, last = state[5], state[6], int(state[7]), int(state[8])
    none = np.empty(0)
    best = -1.0
    came_by = -1  # the move that led to the current pose at the current step size
    while True:
        if best >= cur:
            refinement += 1
            ldelta *= 0.5
            adelta *= 0.5
            came_by = -1
        best = cur
        nx, ny, nt = bx, by, bt
        chosen = -1
        slot = -1  # scratch slot holding the best candidate of this round
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
            w = 1 if slot == 0 else 0
            sc, lk, whole = _score(
                mean, bits, table, tpx0, tpy0, x, y, t, beams, order, cfg, cur, none, dist2,
                cache, w,
            )  # fmt: skip
            if whole and sc > cur:
                cur, cur_like = sc, lk
                nx, ny, nt = x, y, t
                chosen = move
                slot = w
        if chosen >= 0:
            commit_cache(cache, slot)
        bx, by, bt = nx, ny, nt
        came_by = chosen
        if not (cur > best or refinement < last):
            break
    state[0], state[1], state[2], state[3], state[4] = bx, by, bt, cur, cur_like
    state[5], state[6], state[7] = ldelta, adelta, refinement


@njit(cache=True, nogil=True)
def optimize(mean, bits, table, tpx0, tpy0, pose, beams, cfg):
    """Hill climbing from pose (GMapping ScanMatcher::optimize): (pose (3,), score, like,
    score at the start, like at the start).

    Tries steps of +-ldelta in x and y (map frame) and +-adelta in theta, moves to the best
    one while it improves the score, and halves both steps when none does, `iterations` times.
    The step straight back to where the last move came from is not scored again: that pose
    scored lower than the current one, so it can never be chosen. A candidate is dropped as
    soon as it cannot beat the current score, so only the poses it moves to are scored whole.

    Coarse to fine (cfg coarse_skip = s > 0 and coarse_levels = L > 0; off by default): the
    first L step sizes climb on every (s + 1)-th beam only, the remaining ones on all beams
    from where that climb stopped, so the score, likelihood and final pose are GMapping's
    (all beams); only the path of the climb to them is found on fewer beams.
    """
    lstep, astep, iterations = cfg[C_LSTEP], cfg[C_ASTEP], int(cfg[C_ITERATIONS])
    skip, levels = int(cfg[C_COARSE_SKIP]), int(cfg[C_COARSE_LEVELS])
    m = beams.shape[0]
    kernel = int(cfg[C_KERNEL])
    terms = np.empty(m)
    dist2 = np.empty(m)
    natural = np.arange(m)
    cache = new_cache(m, kernel)
    cur, cur_like, _ = _score(
        mean, bits, table, tpx0, tpy0, pose[0], pose[1], pose[2], beams, natural, cfg, -np.inf,
        terms, dist2, cache, 0,
    )  # fmt: skip
    commit_cache(cache, 0)
    start_score, start_like = cur, cur_like
    state = np.array([pose[0], pose[1], pose[2], cur, cur_like, lstep, astep, 0.0, iterations])
    if skip > 0 and levels > 0:
        sub = beams[:: skip + 1].copy()
        ms = sub.shape[0]
        order = np.argsort(terms[:: skip + 1], kind="mergesort")
        state[3], state[4] = 0.0, 0.0
        for k in range(ms):
            state[3] += terms[k * (skip + 1)]
        state[8] = levels - 1
        _climb(
            mean, bits, table, tpx0, tpy0, sub, order, cfg, new_cache(ms, kernel),
            np.empty(ms), state,
        )  # fmt: skip
        # all beams from here, at the next step size
        state[3], state[4], _ = _score(
            mean, bits, table, tpx0, tpy0, state[0], state[1], state[2], beams, natural, cfg,
            -np.inf, terms, dist2, cache, 0,
        )  # fmt: skip
        commit_cache(cache, 0)
        state[5] *= 0.5
        state[6] *= 0.5
        state[7] = levels
        state[8] = iterations
    order = np.argsort(terms, kind="mergesort")  # worst matched first; stable, deterministic
    _climb(mean, bits, table, tpx0, tpy0, beams, order, cfg, cache, dist2, state)
    out = np.array([state[0], state[1], (state[2] + math.pi) % (2 * math.pi) - math.pi])
    return out, state[3], state[4], start_score, start_like
