"""Where the team's shared data sets are (`../shared/` beside the checkout, README there):
the first ancestor of the checkout holding `shared/data/carmen`, so that a worktree one level
deeper (/work/wt/NAME) finds the same data as /work/main; MAPQUAL_SHARED overrides it."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def shared_dir() -> Path:
    """The shared folder (it may not exist: the tests that need it say so and skip)."""
    if os.environ.get("MAPQUAL_SHARED"):
        return Path(os.environ["MAPQUAL_SHARED"])
    for parent in ROOT.parents:
        if (parent / "shared" / "data" / "carmen").is_dir():
            return parent / "shared"
    return ROOT.parent / "shared"


SHARED = shared_dir()
CARMEN = SHARED / "data" / "carmen"
