"""Decompression that counts what it produces: a process-wide budget of output bytes, and the
bag readers' decompressors (rosbag1 bz2/lz4 chunks, MCAP lz4/zstd chunks) bounded by it.

A compressed chunk declares its size, but a forged one may declare 16 bytes and hold 1.5 GB
of zeros; the readers decompress it in one call without a bound. Here every decompression is
a stream stopped one byte past what is left of the budget, so memory and CPU stay bounded by
the budget whatever the file declares. The budget is unlimited (None) unless set: the CLI on a
user's own files is not held back; the sandbox that reads uploads sets it (`set_budget`).
"""

from __future__ import annotations

import bz2
from collections.abc import Callable
from typing import Any

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


def bounded(factory: Callable[[], Any], data: bytes, what: str, size: int | None = None) -> bytes:
    """`data` (one or more concatenated streams) decompressed by decompressors from `factory`
    (bz2 / lz4.frame / zstd objects: `decompress(data, max_length)`, `eof`, `needs_input`,
    `unused_data`), each piece counted against the budget as it comes out; more than `size`
    bytes (a declared size) is refused too."""
    parts: list[bytes] = []
    total = 0
    rest = bytes(data)
    cap = size if size is not None else None
    while True:
        dec = factory()
        piece = dec.decompress(rest, max_length=step(total, cap))
        while True:
            total += len(piece)
            spend(len(piece))
            parts.append(piece)
            if cap is not None and total > cap:
                raise InputError(f"a {what} chunk holds more than the {cap} bytes it declares")
            if dec.eof or dec.needs_input:
                break
            piece = dec.decompress(b"", max_length=step(total, cap))
        if not dec.eof:
            raise InputError(f"a {what} chunk's compressed data ends early")
        rest = dec.unused_data
        if not rest:
            return b"".join(parts)


def step(total: int = 0, cap: int | None = None) -> int:
    """How much the next call may produce: 1 MiB, or one byte past the budget or the cap."""
    step = 1 << 20
    left = budget_left()
    if left is not None:
        step = min(step, left + 1)
    if cap is not None:
        step = min(step, cap - total + 1)
    return max(step, 1)


def _zstd() -> Any:
    try:
        from compression import zstd  # type: ignore[import-not-found]  # Python 3.14
    except ImportError:
        from backports import zstd  # type: ignore[no-redef]
    return zstd.ZstdDecompressor()


def _lz4() -> Any:
    import lz4.frame  # type: ignore[import-untyped]

    return lz4.frame.LZ4FrameDecompressor()


def bound_bag_readers() -> None:
    """Swap the decompressors of rosbags' rosbag1 and MCAP readers for bounded ones (the
    pinned rosbags calls them through these tables; a version without them is refused at
    import, not silently left unbounded)."""
    from rosbags.rosbag1 import reader as r1
    from rosbags.rosbag2 import storage_mcap as mcap

    if not hasattr(r1, "decompressors") or not hasattr(mcap, "DECOMPRESSORS"):
        raise RuntimeError("rosbags has no decompressor tables to bound: check its version")
    r1.decompressors["bz2"] = lambda x: bounded(bz2.BZ2Decompressor, x, "bz2")
    r1.decompressors["lz4"] = lambda x: bounded(_lz4, x, "lz4")
    mcap.DECOMPRESSORS["lz4"] = lambda x, size: bounded(_lz4, x, "lz4", size)
    mcap.DECOMPRESSORS["zstd"] = lambda x, size: bounded(_zstd, x, "zstd", size)
