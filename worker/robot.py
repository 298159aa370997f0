"""The simulated robot's size: what the simulator's parameters default to and worlds check their
start poses against (a constant both read, below either)."""

from __future__ import annotations

FOOTPRINT_M = 0.4  # [m] side of the square robot footprint (Pioneer 3-AT class)
