"""Shared test configuration."""

from __future__ import annotations

import os

import pytest
from hypothesis import settings

# Deterministic property tests: CI must not flake on a newly found example.
settings.register_profile("ci", derandomize=True, deadline=None, max_examples=200)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")


@pytest.fixture
def rng():
    import numpy as np

    return np.random.default_rng(12345)
