"""The process's budget of decompressed bytes, which every bounded decompression spends (the
bag readers' chunks in `worker.export.bounded`, gzip files in `worker.evaluate.textio`).

A forged compressed file may declare 16 bytes and hold 1.5 GB of zeros: each bounded
decompression runs in steps of at most one byte past what is left (`step`), each piece counted
as it comes out (`spend`). Unlimited
(None) unless set: the CLI on a user's own files is not held back; the sandbox that reads
uploads sets it (`set_budget`).
"""

from __future__ import annotations

from worker.errors import InputError


class _Budget:
    """Bytes decompression may still produce in this process (None: unlimited)."""

    left: int | None = None
    limit: int | None = None


_BUDGET = _Budget()


def set_budget(limit: int | None) -> None:
    """From now on, all bounded decompression in this process produces at most `limit` bytes."""
    _BUDGET.left = _BUDGET.limit = limit


def budget_left() -> int | None:
    """What is left of the budget [bytes] (None: unlimited)."""
    return _BUDGET.left


def spend(n: int) -> None:
    """Count `n` bytes produced; InputError past the budget."""
    if _BUDGET.left is None:
        return
    _BUDGET.left -= n
    if _BUDGET.left < 0:
        raise InputError(
            f"the upload decompresses to more than {_BUDGET.limit} bytes in all "
            "(setting upload_unpacked_mb, environment MAPQUAL_UPLOAD_UNPACKED_MB)"
        )


def step(total: int = 0, cap: int | None = None) -> int:
    """How much the next call may produce: 1 MiB, or one byte past the budget or the cap."""
    step = 1 << 20
    left = budget_left()
    if left is not None:
        step = min(step, left + 1)
    if cap is not None:
        step = min(step, cap - total + 1)
    return max(step, 1)
