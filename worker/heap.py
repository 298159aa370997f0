"""Give the C heap's free memory back to the system: after a run, and during one after each
whole-map read and at the exploration's end (worker.explore.loop).

A run's map-sized arrays are freed when it ends, but glibc keeps much of the memory they came
from (and the many small blocks freed with them) in its heap for the next allocation: a 5 s
run on the generated 200 m x 100 m warehouse left 161 MiB of freed memory in the heap of its
process (docs/results/whole-runs.md, "What a warm-up run leaves"), and a Celery worker or a
batch pool process keeps such memory between runs. `malloc_trim(0)` returns every whole free
page of the heap to the system. Other C libraries have no such call; there it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _libc():
    """glibc's handle, or None where the C library is another (musl, macOS)."""
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        libc = ctypes.CDLL(name)
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return libc


def release_free_heap() -> bool:
    """Return the heap's free pages to the system; True when the C library could (glibc)."""
    libc = _libc()
    if libc is None:
        return False
    libc.malloc_trim(0)
    return True
