"""Predictions for the API and the dashboard: a world's features and prediction from the bundled
model, kept per world content in a bounded cache (features take a fraction of a second)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any

from worker.predict.model import load_model, predict
from worker.world.features import world_features
from worker.world.world import World


def predict_world(world: World, slam: str = "rbpf", model: dict[str, Any] | None = None) -> dict:
    """The JSON-ready prediction for `world` (features from the grid alone: uploads keep no
    segmentation image) with the bundled model unless `model` is given."""
    p = predict(model if model is not None else load_model(), world_features(world), slam)
    return {"world": world.name, **p.as_dict()}


class PredictionCache:
    """At most `size` predictions, least recently used dropped first; thread-safe."""

    def __init__(self, size: int = 256):
        self.size = size
        self._items: OrderedDict[tuple, dict] = OrderedDict()
        self._lock = threading.Lock()
        self._model: dict[str, Any] | None = None

    def model(self) -> dict[str, Any]:
        """The bundled model, read once."""
        with self._lock:
            if self._model is None:
                self._model = load_model()
            return self._model

    def get(self, key: tuple, world_of, slam: str) -> dict:
        """The prediction cached under (key, slam), else computed from `world_of()`."""
        full = (*key, slam)
        with self._lock:
            if full in self._items:
                self._items.move_to_end(full)
                return self._items[full]
        out = predict_world(world_of(), slam, self.model())
        with self._lock:
            self._items[full] = out
            while len(self._items) > self.size:
                self._items.popitem(last=False)
        return out
