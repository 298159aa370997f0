"""Gradient-boosted regression trees as plain JSON and their evaluation in numpy: the model
file holds no pickle, and predicting needs no scikit-learn."""

from __future__ import annotations

from typing import Any

import numpy as np

from worker.errors import InputError

LEAF = -1  # scikit-learn's TREE_LEAF: a node without children


def export_gbr(model: Any) -> dict[str, Any]:
    """A fitted sklearn GradientBoostingRegressor as JSON data: the constant it starts from,
    the learning rate and each tree's node arrays (left, right, feature, threshold, value)."""
    init = model.init_
    base = float(np.ravel(getattr(init, "constant_", [[0.0]]))[0])
    trees = []
    for est in model.estimators_[:, 0]:
        t = est.tree_
        trees.append(
            {
                "left": t.children_left.tolist(),
                "right": t.children_right.tolist(),
                "feature": t.feature.tolist(),
                "threshold": [float(v) for v in t.threshold],
                "value": [float(v) for v in t.value[:, 0, 0]],
            }
        )
    return {"init": base, "learning_rate": float(model.learning_rate), "trees": trees}


def _tree_predict(tree: dict[str, Any], X: np.ndarray) -> np.ndarray:
    """One tree's leaf values for `X` `(N, F)`: all rows descend a level at a time."""
    left = np.asarray(tree["left"], dtype=np.int64)
    right = np.asarray(tree["right"], dtype=np.int64)
    feature = np.asarray(tree["feature"], dtype=np.int64)
    threshold = np.asarray(tree["threshold"], dtype=np.float64)
    value = np.asarray(tree["value"], dtype=np.float64)
    node = np.zeros(X.shape[0], dtype=np.int64)
    rows = np.arange(X.shape[0])
    for _ in range(len(left)):  # depth is at most the node count
        inner = left[node] != LEAF
        if not inner.any():
            break
        f = np.where(inner, feature[node], 0)
        go_left = X[rows, f] <= threshold[node]  # sklearn's rule: x <= threshold goes left
        node = np.where(inner, np.where(go_left, left[node], right[node]), node)
    return value[node]


def predict_gbr(data: dict[str, Any], X: np.ndarray) -> np.ndarray:
    """`(N,)` predictions of an exported GradientBoostingRegressor for `X` `(N, F)`."""
    try:
        out = np.full(X.shape[0], float(data["init"]))
        rate = float(data["learning_rate"])
        for tree in data["trees"]:
            out += rate * _tree_predict(tree, X)
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InputError(f"model file: malformed tree ensemble ({exc})") from None
    return out
