"""The C heap's free pages go back to the system after a run (worker.heap), as glibc's own
accounting and the process's resident size both show."""

from __future__ import annotations

import subprocess
import sys

import pytest

from worker.heap import _libc

# Frees 256 MB of 4,000-byte blocks (malloc'ed, below the mmap threshold: from the heap) that
# lie below a block still in use, so glibc cannot hand them back by shrinking the heap's top:
# they stay resident until malloc_trim returns their pages. Prints the resident size [MiB]
# before and after the call.
_PROBE = """
import os
from worker.heap import release_free_heap

def rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

blocks = [bytes(4000) for _ in range(64_000)]
pin = bytes(4000)  # above the blocks
del blocks
before = rss()
assert release_free_heap()
print(before, rss())
"""


@pytest.mark.skipif(_libc() is None, reason="malloc_trim is glibc's; this C library has none")
def test_freed_heap_memory_is_returned_to_the_system():
    out = subprocess.run(
        [sys.executable, "-c", _PROBE], capture_output=True, text=True, check=True
    ).stdout
    before, after = (float(v) for v in out.split())
    assert before - after > 200, (before, after)  # of the 244 MiB freed
