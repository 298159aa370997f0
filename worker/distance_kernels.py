"""Bounded exact distance transform (numba): per cell, a value looked up by the squared
distance to the nearest source cell within R cells. The costmap inflates with it
(worker.explore.costmap_kernels) and the coverage finds the cells the robot can reach with it
(worker.evaluate.coverage), in memory of a band of rows instead of a whole-plan transform."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def inflate_region(lethal, kernel, cost, y0, y1, x0, x1):
    """Recompute `cost[y0:y1, x0:x1]` from the lethal cells that can reach it (in place).

    lethal: (H, W) bool; kernel: (2R+1, 2R+1) uint8 stamp; cost: (H, W) uint8 inflated costs.
    A cell's cost is the kernel's value at its nearest obstacle within the kernel's square,
    what costmap_2d's brushfire computes (nearest obstacle -> highest cost). Exact: first, per
    row, the distance to the nearest obstacle in that row within R (two sweeps); then, per
    column, the least dy^2 + row distance^2 over the rows, by the lower envelope of parabolas
    (Meijster's exact distance transform, integer arithmetic), in O(1) per cell. The kernel is
    0 past R cells (`effective_inflation_cells`), so an obstacle farther than R in a row or
    in a column changes no cost, and the rows past R that the envelope also looks at cannot
    lower a cost under R^2.
    """
    h, w = lethal.shape
    r = kernel.shape[0] // 2
    if y1 <= y0 or x1 <= x0:
        return
    # cost by squared cell distance (the kernel depends on the distance only)
    table = np.zeros(2 * r * r + 1, dtype=np.uint8)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            table[dy * dy + dx * dx] = kernel[dy + r, dx + r]
    ry0 = max(0, y0 - r)
    ry1 = min(h, y1 + r)
    hd = _row_distances(lethal, r, ry0, ry1, x0, x1)
    n = ry1 - ry0
    inf = np.int64(1) << 40  # "no obstacle within R in this row"
    f = np.empty(n, dtype=np.int64)
    s = np.empty(n, dtype=np.int64)  # the envelope's parabolas (rows) ...
    t = np.empty(n, dtype=np.int64)  # ... and where each starts
    for j in range(x1 - x0):
        for u in range(n):
            d = hd[u, j]
            f[u] = d * d if d <= r else inf
        q = 0
        s[0] = 0
        t[0] = 0
        for u in range(1, n):
            while q >= 0 and (t[q] - s[q]) ** 2 + f[s[q]] > (t[q] - u) ** 2 + f[u]:
                q -= 1
            if q < 0:
                q = 0
                s[0] = u
            else:
                i = s[q]
                start = 1 + (u * u - i * i + f[u] - f[i]) // (2 * (u - i))
                if start < n:
                    q += 1
                    s[q] = u
                    t[q] = start
        for u in range(n - 1, -1, -1):
            iy = ry0 + u
            if y0 <= iy < y1:
                best = (u - s[q]) ** 2 + f[s[q]]
                cost[iy, x0 + j] = table[best] if best <= r * r else 0
            if u == t[q]:
                q -= 1


@njit(cache=True)
def _row_distances(lethal, r, ry0, ry1, x0, x1):
    """`(ry1 - ry0, x1 - x0) int64`: per row, the distance [cells] from each cell of
    `[x0, x1)` to the nearest lethal cell in that row, R + 1 where none lies within R."""
    w = lethal.shape[1]
    far = r + 1
    cx0 = max(0, x0 - r)
    cx1 = min(w, x1 + r)
    hd = np.empty((ry1 - ry0, x1 - x0), dtype=np.int64)
    for yy in range(ry0, ry1):
        row = hd[yy - ry0]
        last = -(10**9)
        for xx in range(cx0, x1):  # nearest obstacle to the left (or here)
            if lethal[yy, xx]:
                last = xx
            if xx >= x0:
                row[xx - x0] = min(far, xx - last)
        last = 10**9
        for xx in range(cx1 - 1, x0 - 1, -1):  # and to the right
            if lethal[yy, xx]:
                last = xx
            if xx < x1:
                d = last - xx
                if d < row[xx - x0]:
                    row[xx - x0] = d
    return hd
