"""numba kernel: whitespace-separated decimal tables parsed straight from bytes (fast path).

Only the plain decimal forms the relation and trajectory writers emit are accepted
(`-12.345`, `.5`, `3.`, `1e-3`); anything else (nan, inf, hex, a word, more significant
digits than a double holds exactly) makes the kernel give up, and the caller falls back to
numpy's parser and its line-by-line error report. Accepted numbers are correctly rounded:
an integer mantissa below 2**53 scaled once by an exact power of ten <= 1e22 is a single
IEEE operation (Clinger's fast path), so the result equals Python's `float(text)`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

OK = 0
GIVE_UP = 1  # not a plain decimal table of ncols columns: let numpy parse it and report

_POW10 = np.array([10.0**k for k in range(23)])
_MAX_EXACT = 2**53


@njit(cache=True)
def _space(c: int) -> bool:
    return c == 32 or c == 9 or c == 13  # ' ', '\t', '\r'


@njit(cache=True)
def parse_decimal_table(buf: np.ndarray, ncols: int):
    """Rows of `ncols` numbers from the bytes `buf (B,) uint8` of a text file; blank lines
    and `#` comments skipped. Returns (table (K, ncols), status): status OK or GIVE_UP."""
    n = buf.shape[0]
    lines = 1
    for i in range(n):
        if buf[i] == 10:
            lines += 1
    out = np.empty((lines, ncols))
    row = 0
    col = 0
    i = 0
    while i <= n:
        c = buf[i] if i < n else 10
        if c == 10:  # end of line (or of the file)
            if col != 0 and col != ncols:
                return out[:0], GIVE_UP
            if col == ncols:
                row += 1
            col = 0
            i += 1
        elif _space(c):
            i += 1
        elif c == 35:  # '#': skip to the end of the line
            while i < n and buf[i] != 10:
                i += 1
        else:
            if col == ncols:
                return out[:0], GIVE_UP
            # sign, digits, '.', digits, optional exponent
            neg = False
            if c == 45 or c == 43:
                neg = c == 45
                i += 1
            mant = 0
            digits = 0
            frac = 0
            seen_dot = False
            while i < n:
                c = buf[i]
                if 48 <= c <= 57:
                    if mant >= _MAX_EXACT // 10:  # would not stay exact
                        return out[:0], GIVE_UP
                    mant = mant * 10 + (c - 48)
                    digits += 1
                    if seen_dot:
                        frac += 1
                    i += 1
                elif c == 46 and not seen_dot:
                    seen_dot = True
                    i += 1
                else:
                    break
            if digits == 0:
                return out[:0], GIVE_UP
            exp = 0
            if i < n and (buf[i] == 101 or buf[i] == 69):  # 'e' / 'E'
                i += 1
                eneg = False
                if i < n and (buf[i] == 45 or buf[i] == 43):
                    eneg = buf[i] == 45
                    i += 1
                edigits = 0
                while i < n and 48 <= buf[i] <= 57:
                    exp = exp * 10 + (buf[i] - 48)
                    edigits += 1
                    if exp > 400:
                        return out[:0], GIVE_UP
                    i += 1
                if edigits == 0:
                    return out[:0], GIVE_UP
                if eneg:
                    exp = -exp
            if i < n and not (_space(buf[i]) or buf[i] == 10 or buf[i] == 35):
                return out[:0], GIVE_UP  # e.g. "1.2.3", "12abc", "nan"
            k = exp - frac
            if k < -22 or k > 22:
                return out[:0], GIVE_UP
            v = float(mant)
            v = v / _POW10[-k] if k < 0 else v * _POW10[k]
            out[row, col] = -v if neg else v
            col += 1
    return out[:row], OK
