"""The prediction cache: computed once per (world content, algorithm), least recently used
dropped first; failures kept, requests at once sharing one computation, an unknown algorithm
refused before any work."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from worker.errors import InputError
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


def _open_world() -> World:
    """Free space to the image's edge: no enclosed free space to compute features on."""
    occ = np.zeros((40, 60), bool)
    occ[20, 10:50] = True
    return World.from_array(occ, 0.05, name="open")


def test_an_unknown_algorithm_is_refused_before_any_feature_work():
    calls = []
    cache = PredictionCache()
    with pytest.raises(InputError, match="no 'bogus7' part"):
        cache.get((1, "x"), lambda: calls.append(1) or _world(), "bogus7")
    assert calls == []


def test_a_failure_is_computed_once_and_kept():
    calls = []

    def world_of():
        calls.append(1)
        return _open_world()

    cache = PredictionCache()
    with pytest.raises(InputError) as first:
        cache.get((1, "open"), world_of, "rbpf")
    with pytest.raises(InputError) as again:
        cache.get((1, "open"), world_of, "rbpf")
    assert str(again.value) == str(first.value) and len(calls) == 1


def test_requests_at_once_share_one_computation():
    calls = []
    gate = threading.Event()

    def world_of():
        calls.append(1)
        gate.wait(5)  # every request is in before the first computation ends
        return _world()

    cache = PredictionCache(workers=4)
    with ThreadPoolExecutor(4) as ex:
        futures = [ex.submit(cache.get, (9, "w"), world_of, "rbpf") for _ in range(4)]
        time.sleep(0.3)
        gate.set()
        outs = [f.result(10) for f in futures]
    assert len(calls) == 1 and all(o is outs[0] for o in outs)
