"""The prediction cache: computed once per (world content, algorithm), least recently used
dropped first."""

from __future__ import annotations

import numpy as np

from worker.predict.service import PredictionCache
from worker.world.world import World


def _world() -> World:
    occ = np.zeros((62, 102), bool)  # 3 m x 5 m room
    occ[[0, -1], :] = True
    occ[:, [0, -1]] = True
    return World.from_array(occ, 0.05, name="room")


def test_cache_computes_once_per_key_and_drops_the_oldest():
    calls = []

    def world_of():
        calls.append(1)
        return _world()

    cache = PredictionCache(size=2)
    a = cache.get((1, "x"), world_of, "rbpf")
    assert cache.get((1, "x"), world_of, "rbpf") is a and len(calls) == 1
    assert a["features"]["free_area_m2"] == 3 * 5 and a["world"] == "room"
    cache.get((2, "y"), world_of, "rbpf")
    cache.get((3, "z"), world_of, "rbpf")  # drops (1, "x")
    cache.get((1, "x"), world_of, "rbpf")
    assert len(calls) == 4
