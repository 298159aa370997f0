"""The order of a log's samples by their clock: the one rule every log and trajectory reader uses.

Real logs are not clean (issue 17): timestamps step back by a few hundredths of a second, a
logger writes the same message twice, and some clocks are printed too coarsely to order the
samples at all (the MIT CSAIL corrected log prints Unix time with six significant digits,
`1.13486e+09`: hundreds of scans share one timestamp, then it jumps by 10,000 s). The rule:

1. Exact duplicates (same timestamp and same content as an earlier sample) are dropped.
2. The clock is *degenerate* when more than DEGENERATE_TIE_SHARE (and at least
   DEGENERATE_MIN_TIES) of the remaining consecutive samples (in file order) share a
   timestamp: it can neither order nor space them. The samples then keep their file order
   and get times from their index at the log's nominal rate,
   t_k = t_first + k * period, period = (t_max - t_min) / (n - 1), or 1 s when all times are
   equal. One warning says so.
3. Otherwise the samples are sorted by time, stably (equal times keep their file order), with
   a warning counting the samples that were out of order.

Ground truth and estimate read from the same lines get the same times, so relations pair the
right poses (`mapqual slam` writes its estimate at these times).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from worker.errors import InputWarning

DEGENERATE_TIE_SHARE = 0.05  # a clock tying more than this share of consecutive samples
DEGENERATE_MIN_TIES = 10  # ... and at least this many (a short file's one tie is not a clock)
DEFAULT_PERIOD_S = 1.0  # [s] spacing of the index clock when every timestamp is the same


@dataclass(frozen=True, eq=False)
class ClockOrder:
    """Which samples to keep, in which order, at which times.

    index: (K,) indices into the samples as read; t: (K,) [s] their times (sorted, or the
    index clock); duplicates: exact duplicates dropped; out_of_order: samples that came
    before an earlier timestamp; degenerate: the index clock was used.
    """

    index: NDArray[np.int64]
    t: NDArray[np.float64]
    duplicates: int
    out_of_order: int
    degenerate: bool

    def notes(self, what: str) -> list[str]:
        """One-line warnings, `what` naming the samples ("scans", "poses")."""
        out = []
        if self.duplicates:
            out.append(f"{self.duplicates} exact duplicate {what} dropped")
        if self.degenerate:
            period = float(self.t[1] - self.t[0]) if self.t.shape[0] > 1 else DEFAULT_PERIOD_S
            out.append(
                f"the clock cannot order the {what} (more than {DEGENERATE_TIE_SHARE:.0%} share "
                f"a timestamp): times taken from the {what[:-1]} index, {period:.6g} s apart "
                "(the log's span over its count), in file order"
            )
        elif self.out_of_order:
            out.append(f"{self.out_of_order} {what} out of time order: sorted (stable)")
        return out


def _duplicate_mask(t: NDArray[np.float64], content: NDArray) -> NDArray[np.bool_]:
    """True for each sample whose timestamp and content equal an earlier sample's."""
    rows = np.column_stack([t.reshape(-1, 1), content.reshape(t.shape[0], -1)])
    _, first = np.unique(rows, axis=0, return_index=True)
    dup = np.ones(t.shape[0], dtype=bool)
    dup[first] = False
    return dup


def clock_order(t: NDArray[np.float64], content: NDArray) -> ClockOrder:
    """The rule above for samples at times `t (N,)` whose data are the rows of `content`
    `(N, ...)` (compared for exact duplicates; a pose, or a pose and a scan)."""
    t = np.asarray(t, dtype=np.float64)
    n = t.shape[0]
    if n == 0:
        return ClockOrder(np.zeros(0, dtype=np.int64), t, 0, 0, False)
    keep = np.flatnonzero(~_duplicate_mask(t, np.asarray(content, dtype=np.float64)))
    tk = t[keep]
    steps = np.diff(tk)
    ties = int(np.count_nonzero(steps == 0.0))
    if ties >= DEGENERATE_MIN_TIES and ties > DEGENERATE_TIE_SHARE * steps.shape[0]:
        span = float(tk.max() - tk.min())
        period = span / (tk.shape[0] - 1) if span > 0 else DEFAULT_PERIOD_S
        times = tk[0] + period * np.arange(tk.shape[0], dtype=np.float64)
        return ClockOrder(keep, times, n - keep.shape[0], 0, True)
    order = np.argsort(tk, kind="stable")
    # a sample is out of order when an earlier one (in the file) has a later time
    late = int(np.count_nonzero(tk < np.maximum.accumulate(tk)))
    return ClockOrder(keep[order], tk[order], n - keep.shape[0], late, False)


def warn_notes(notes: list[str], source: str) -> None:
    """Each note as one InputWarning naming the file."""
    for note in notes:
        warnings.warn(InputWarning(f"{source}: {note}"), stacklevel=3)
