"""The pipeline: worlds, simulator, exploration, SLAM and evaluation (pure numpy/numba).

Importing it points numba's on-disk cache at a folder named after the source files of this
package (their paths, sizes and modification times), unless NUMBA_CACHE_DIR is set already.
numba checks a cached kernel against its own file only, not against the files of the kernels
it calls: after `git pull` or an edit that changed `worker/slam/match_kernels.py` alone,
`match_all_kernels.scan_match_all` ran the old hill climbing from its cache, silently. With
the folder named after every file, any change to the package compiles afresh.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

_KEEP = 3  # cache folders kept (the newest), for checkouts switched back and forth


def numba_cache_dir(package: Path) -> Path:
    """The numba cache folder of `package`'s sources as they are now (under its __pycache__)."""
    h = hashlib.blake2b(digest_size=8)
    for path in sorted(package.rglob("*.py")):
        st = path.stat()
        h.update(f"{path.relative_to(package)}\0{st.st_size}\0{st.st_mtime_ns}\n".encode())
    return package / "__pycache__" / f"numba-{h.hexdigest()}"


def _use_numba_cache_dir() -> None:
    if "NUMBA_CACHE_DIR" in os.environ:
        return
    package = Path(__file__).resolve().parent
    try:
        here = numba_cache_dir(package)
        older = sorted(
            (p for p in here.parent.glob("numba-*") if p != here and p.is_dir()),
            key=lambda p: p.stat().st_mtime,
        )
        if len(older) >= _KEEP:
            import shutil  # only then: the API's import stays lean

            for stale in older[: len(older) - (_KEEP - 1)]:
                shutil.rmtree(stale, ignore_errors=True)
        here.mkdir(parents=True, exist_ok=True)
        if not os.access(here, os.W_OK):
            return
    except OSError:  # a read-only or vanished tree: numba's own default then
        return
    os.environ["NUMBA_CACHE_DIR"] = str(here)


_use_numba_cache_dir()
