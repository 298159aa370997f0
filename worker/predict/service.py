"""Predictions for the API and the dashboard: a world's features and prediction from the bundled
model, kept per world content in a bounded cache (features take a fraction of a second, seconds
on a 24 MP plan), failures included."""

from __future__ import annotations

import concurrent.futures as cf
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from worker.errors import InputError
from worker.predict.model import load_model

if TYPE_CHECKING:
    from worker.world.world import World

# How a cache computes a prediction: (what `get` was given, the algorithm, the model) -> it.
Compute = Callable[[Callable[[], "World"], str, dict[str, Any]], dict]


def predict_world(world: World, slam: str = "rbpf", model: dict[str, Any] | None = None) -> dict:
    """The JSON-ready prediction for `world` (features from the grid alone: uploads keep no
    segmentation image) with the bundled model unless `model` is given."""
    from worker.predict.model import predict
    from worker.world.features import world_features  # numba: where predictions are made

    p = predict(model if model is not None else load_model(), world_features(world), slam)
    return {"world": world.name, **p.as_dict()}


def _in_process(world_of: Callable[[], World], slam: str, model: dict[str, Any]) -> dict:
    return predict_world(world_of(), slam, model)


class PredictionCache:
    """At most `size` outcomes (a prediction, or the one-line reason none can be made), least
    recently used dropped first; thread-safe. Computed in a pool of `workers` threads, one
    computation per (world content, algorithm) however many requests ask at once (the others
    wait for it); an algorithm the model has no part for is refused before any feature work.
    `compute` makes a prediction from `get`'s `world_of` (default: the World it returns,
    here; the API's computes in a limited process of its own).
    """

    def __init__(self, size: int = 256, workers: int = 1, compute: Compute = _in_process):
        self.size = size
        self._compute_one = compute
        self._items: OrderedDict[tuple, tuple[bool, Any]] = OrderedDict()
        self._flights: dict[tuple, cf.Future[tuple[bool, Any]]] = {}
        self._lock = threading.Lock()
        self._model: dict[str, Any] | None = None
        self._pool = cf.ThreadPoolExecutor(workers, thread_name_prefix="mapqual-predict")

    def model(self) -> dict[str, Any]:
        """The bundled model, read once."""
        with self._lock:
            if self._model is None:
                self._model = load_model()
            return self._model

    def get(self, key: tuple, world_of: Callable[[], World], slam: str) -> dict:
        """The prediction cached under (key, slam), else computed from `world_of()` (once,
        whoever else asks meanwhile); InputError, cached too, when none can be made."""
        model = self.model()
        parts = model.get("slam", {})
        if slam not in parts:
            have = ", ".join(sorted(parts)) or "none"
            raise InputError(f"the model has no {slam!r} part (it has: {have})")
        full = (*key, slam)
        with self._lock:
            if full in self._items:
                self._items.move_to_end(full)
                return _outcome(self._items[full])
            flight = self._flights.get(full)
            if flight is None:
                flight = self._pool.submit(self._compute, full, world_of, slam, model)
                self._flights[full] = flight
        return _outcome(flight.result())

    def _compute(
        self, full: tuple, world_of: Callable[[], World], slam: str, model: dict[str, Any]
    ) -> tuple[bool, Any]:
        try:
            out: tuple[bool, Any] = (True, self._compute_one(world_of, slam, model))
        except InputError as exc:  # the world's own fault: as lasting as the world's content
            out = (False, str(exc))
        except BaseException:
            with self._lock:
                self._flights.pop(full, None)  # a fault of ours: the next request tries again
            raise
        with self._lock:
            self._items[full] = out
            self._flights.pop(full, None)
            while len(self._items) > self.size:
                self._items.popitem(last=False)
        return out


def _outcome(item: tuple[bool, Any]) -> dict:
    ok, value = item
    if not ok:
        raise InputError(value)
    return value
