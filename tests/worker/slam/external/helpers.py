"""Commands of the test programs, and the child processes a test leaves behind."""

from __future__ import annotations

import contextlib
import os
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[3]
EXAMPLE = ROOT / "examples" / "external_slam" / "dead_reckoning_slam.py"


def fake(mode: str, step: int = 3) -> list[str]:
    """argv of the misbehaving program (tests/worker/slam/external/fake_program.py)."""
    return [sys.executable, str(HERE / "fake_program.py"), mode, str(step)]


def example() -> list[str]:
    return [sys.executable, str(EXAMPLE)]


def twin(algorithm: str = "odometry") -> list[str]:
    return [sys.executable, "-m", "worker.slam.external.twin", algorithm]


def children() -> set[int]:
    """Process ids whose parent is this process (zombies included: they are still listed)."""
    out: set[int] = set()
    for task in Path(f"/proc/{os.getpid()}/task").iterdir():
        with contextlib.suppress(OSError):
            out |= {int(p) for p in (task / "children").read_text().split()}
    return out
