"""numba's on-disk cache follows every source file of the package, not only the kernel's own:
a kernel that calls a kernel of another file is compiled afresh when that file changes."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import worker
from worker import numba_cache_dir

ROOT = Path(__file__).resolve().parents[2]

CALLER = """
from numba import njit
from pkg.callee import g

@njit(cache=True)
def f(x):
    return g(x) + 1
"""
CALLEE = """
from numba import njit

@njit(cache=True)
def g(x):
    return x * {factor}
"""
RUN = """
import os, sys
sys.path.insert(0, {tmp!r})
if {keyed}:
    sys.path.insert(0, {root!r})
    from worker import numba_cache_dir
    from pathlib import Path
    os.environ["NUMBA_CACHE_DIR"] = str(numba_cache_dir(Path({tmp!r}) / "pkg"))
from pkg.caller import f
print(f(10))
"""


def _package(tmp: Path, factor: int) -> None:
    pkg = tmp / "pkg"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    callee = pkg / "callee.py"
    text = CALLEE.format(factor=factor)
    if callee.exists():  # a later edit: another size and a later modification time
        st = callee.stat()
        callee.write_text(text)
        os.utime(callee, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    else:
        callee.write_text(text)


def _f_of_10(tmp: Path, keyed: bool) -> int:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    code = RUN.format(tmp=str(tmp), root=str(ROOT), keyed=keyed)
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return int(out.stdout.split()[-1])


def test_a_callee_edited_in_another_file_is_compiled_afresh(tmp_path):
    for keyed, stale_answer in ((False, 21), (True, 31)):
        tmp = tmp_path / ("keyed" if keyed else "plain")
        tmp.mkdir()
        _package(tmp, factor=2)
        assert _f_of_10(tmp, keyed) == 21
        _package(tmp, factor=3)  # only the callee's file changes
        # numba alone keeps the caller's cached machine code with the old callee inside;
        # keyed by every file of the package, the caller is compiled again
        assert _f_of_10(tmp, keyed) == stale_answer


def test_the_folder_follows_the_files_and_a_set_variable_wins(tmp_path):
    _package(tmp_path, factor=2)
    pkg = tmp_path / "pkg"
    first = numba_cache_dir(pkg)
    assert first == numba_cache_dir(pkg) and first.parent == pkg / "__pycache__"
    _package(tmp_path, factor=3)
    assert numba_cache_dir(pkg) != first
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "mine")}
    code = "import os, worker; print(os.environ['NUMBA_CACHE_DIR'])"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.stdout.strip() == str(tmp_path / "mine")  # Docker's NUMBA_CACHE_DIR stays
    env.pop("NUMBA_CACHE_DIR")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert out.stdout.strip() == str(numba_cache_dir(Path(worker.__file__).parent))
