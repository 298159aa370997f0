"""The bag readers' decompressors (rosbag1 bz2/lz4 chunks, MCAP lz4/zstd chunks) bounded by the
process's budget of decompressed bytes.

A compressed chunk declares its size, but a forged one may declare 16 bytes and hold 1.5 GB
of zeros; the readers decompress it in one call without a bound. Here every decompression is
a stream stopped one byte past what is left of the budget, so memory and CPU stay bounded by
the budget whatever the file declares. The budget (`worker.decompress_budget`) is unlimited
(None) unless set: the CLI on a user's own files is not held back; the sandbox that reads
uploads sets it (`set_budget`).
"""

from __future__ import annotations

import bz2
from collections.abc import Callable
from typing import Any

from worker.decompress_budget import spend, step
from worker.errors import InputError


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
