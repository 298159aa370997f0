"""The fixed-point range formatter against Python's own formatting."""

from __future__ import annotations

import numpy as np
import pytest

from worker.sim.format_kernels import format_fixed3


def test_matches_percent_format_away_from_ties(rng):
    values = rng.uniform(0.0, 30.0, 5000)
    # Keep away from exact half-millimetre ties, where rounding rules may legitimately differ.
    frac = (values * 1000.0) % 1.0
    values = values[np.abs(frac - 0.5) > 1e-3]
    expected = " ".join(f"{v:.3f}" for v in values)
    assert format_fixed3(values) == expected


def test_edge_values():
    assert format_fixed3(np.array([0.0, 30.0, 1234.5678, 0.0004, -2.5])) == (
        "0.000 30.000 1234.568 0.000 -2.500"
    )
    assert format_fixed3(np.array([])) == ""
    with pytest.raises(ValueError):
        format_fixed3(np.array([np.nan]))
