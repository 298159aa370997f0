"""Fast fixed-point ASCII formatting of range readings for CARMEN logs (numba)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _format_fixed3(values, out):
    """Write `values` as space-separated decimals with 3 fractional digits into `out` (uint8,
    at least 22 bytes per value). Rounds half away from zero at the third decimal.

    Returns the number of bytes written, or -1 (nothing usable) if a value is not finite or
    not below 1e15 in magnitude.
    """
    pos = 0
    digits = np.empty(20, dtype=np.uint8)
    for i in range(values.shape[0]):
        v = values[i]
        if not (abs(v) < 1e15):  # also catches nan
            return -1
        if i > 0:
            out[pos] = 32  # ' '
            pos += 1
        m = int(math.floor(abs(v) * 1000.0 + 0.5))
        if v < 0.0 and m != 0:
            out[pos] = 45  # '-'
            pos += 1
        whole = m // 1000
        frac = m - whole * 1000
        n = 0
        while True:
            digits[n] = 48 + whole % 10
            n += 1
            whole //= 10
            if whole == 0:
                break
        for k in range(n - 1, -1, -1):
            out[pos] = digits[k]
            pos += 1
        out[pos] = 46  # '.'
        out[pos + 1] = 48 + frac // 100
        out[pos + 2] = 48 + (frac // 10) % 10
        out[pos + 3] = 48 + frac % 10
        pos += 4
    return pos


class Fixed3Formatter:
    """Formats arrays as 'a.bcd e.fgh ...' (3 decimals, half away from zero), reusing one
    buffer across calls (a log writes thousands of scans of the same size)."""

    def __init__(self) -> None:
        self._buf = np.empty(0, dtype=np.uint8)

    def __call__(self, values: np.ndarray) -> str:
        values = np.ascontiguousarray(values, dtype=np.float64)
        need = values.shape[0] * 22 + 1
        if self._buf.shape[0] < need:
            self._buf = np.empty(need, dtype=np.uint8)
        n = _format_fixed3(values, self._buf)
        if n < 0:
            raise ValueError("format_fixed3 needs finite values below 1e15")
        return self._buf[:n].tobytes().decode("ascii")


def format_fixed3(values: np.ndarray) -> str:
    """`values` `(B,)` as 'a.bcd e.fgh ...' (3 decimals, half away from zero), finite only."""
    return Fixed3Formatter()(values)
