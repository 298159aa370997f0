"""The scan matcher's cell cache, in numba: each beam's matching cells (their hit means, after
the occupancy and free-cell tests) remembered for the current pose of the hill climbing, keyed
by the end-point cell and free-cell offset, so that a candidate pose whose end point stays in
the same cell reuses them (`worker.slam.match_kernels`)."""

from __future__ import annotations

import numpy as np
from numba import njit

MAX_CACHED_KERNEL = 2  # [cells] the cell cache keeps up to (2k+1)^2 points per beam


@njit(cache=True, nogil=True)
def new_cache(m, kernel):
    """The matching-cell cache of m beams: (key (M,), count (M,), points (M, K, 2) [m]) for the
    current pose, and two scratch slots of the same plus their lists of recorded beams.
    K = (2 kernel + 1)^2; K = 0 (no caching) for kernels above MAX_CACHED_KERNEL."""
    k = (2 * kernel + 1) ** 2 if kernel <= MAX_CACHED_KERNEL else 0
    return (
        np.full(m, -1, dtype=np.int64),
        np.zeros(m, dtype=np.int64),
        np.empty((m, k, 2)),
        np.full((2, m), -1, dtype=np.int64),
        np.zeros((2, m), dtype=np.int64),
        np.empty((2, m, k, 2)),
        np.empty((2, m), dtype=np.int64),
        np.zeros(2, dtype=np.int64),
    )


@njit(cache=True, nogil=True)
def commit_cache(cache, slot):
    """The pose scored into scratch `slot` becomes the current one: its entries are kept."""
    ckey, cn, cpts, skey, sn, spts, smiss, snmiss = cache
    for q in range(snmiss[slot]):
        i = smiss[slot, q]
        ckey[i] = skey[slot, i]
        cn[i] = sn[slot, i]
        for r in range(sn[slot, i]):
            cpts[i, r, 0] = spts[slot, i, r, 0]
            cpts[i, r, 1] = spts[slot, i, r, 1]
