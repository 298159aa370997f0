"""The model pieces against independent references: exported trees against scikit-learn's own
predict, the ridge fit against a known linear law, the success rate against Laplace's rule,
cross-validation on a target that free area alone ranks."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.ensemble import GradientBoostingRegressor

from worker.errors import InputError
from worker.predict.crossval import conformal_margin, leave_one_building_out, spearman
from worker.predict.dataset import Dataset, building_of
from worker.predict.model import FORMAT, VERSION, _target, linear_predict, load_model
from worker.predict.train import TrainParams, fit_linear, fit_success
from worker.predict.trees import export_gbr, predict_gbr


@pytest.mark.parametrize("q", [0.1, 0.5, 0.9])
def test_exported_trees_predict_what_sklearn_predicts(q):
    rng = np.random.default_rng(4)
    X = rng.normal(size=(80, 5))
    y = X[:, 0] ** 2 - 2 * X[:, 1] + rng.normal(0, 0.1, 80)
    model = GradientBoostingRegressor(loss="quantile", alpha=q, n_estimators=40, max_depth=3,
                                      random_state=0).fit(X, y)  # fmt: skip
    data = json.loads(json.dumps(export_gbr(model)))  # through JSON, as stored
    Xt = rng.normal(size=(50, 5))
    np.testing.assert_allclose(predict_gbr(data, Xt), model.predict(Xt), rtol=0, atol=1e-12)


def test_ridge_recovers_a_linear_law():
    rng = np.random.default_rng(1)
    X = rng.uniform(0, 10, size=(60, 3))
    y = 3.0 + 2.0 * X[:, 0] - X[:, 1]  # the third column is irrelevant
    lin = fit_linear(X, y, TrainParams(ridge_alphas=(1e-9,)))
    x = np.array([1.5, 4.0, 7.0])
    assert linear_predict(lin, x)[0] == pytest.approx(3.0 + 3.0 - 4.0, abs=1e-6)
    assert abs(lin["coef"][2]) < 1e-6


def test_success_is_laplace_rate_when_every_run_ended_alike():
    X = np.arange(8.0).reshape(4, 2)
    spec = fit_success(X, np.array([2, 2, 2, 2]), np.array([2, 2, 2, 2]), TrainParams())
    assert spec == {"kind": "constant", "probability": pytest.approx(9 / 10)}


def test_success_rises_with_the_feature_it_follows():
    X = np.array([[0.0], [1.0], [2.0], [3.0], [4.0], [5.0]])
    completed, runs = np.array([0, 0, 1, 1, 2, 2]), np.full(6, 2)
    spec = fit_success(X, completed, runs, TrainParams())
    assert spec["kind"] == "logistic" and spec["coef"][0] > 0


def _dataset(area: np.ndarray, noise: np.ndarray, y: np.ndarray) -> Dataset:
    worlds = tuple(f"b{i // 2}" + ("_furnitures" if i % 2 else "") for i in range(len(y)))
    X = np.column_stack([area, noise])
    return Dataset("rbpf", ("free_area_m2", "noise"), worlds,
                   tuple(building_of(w) for w in worlds), X, y, y / 30, np.ones(len(y), int),
                   np.ones(len(y), int))  # fmt: skip


def test_cv_holds_a_building_out_with_its_furnished_variant():
    rng = np.random.default_rng(2)
    area = np.sort(rng.uniform(100, 3000, 24))
    y = 0.05 * np.exp(area / 1000)  # error grows with area: free area alone ranks it
    cv = leave_one_building_out(_dataset(area, rng.normal(size=24), y))
    s = cv.scores()
    assert s["free_area"]["spearman_worlds"] == pytest.approx(1.0)
    assert s["free_area"]["mae"] < s["mean"]["mae"]
    assert s["trees"]["spearman_worlds"] > 0.9 and s["linear"]["spearman_worlds"] > 0.9
    # the training-mean baseline of a held-out pair never saw that pair's values
    held = np.array(cv.buildings) == "b0"
    assert cv.predicted["mean"][held][0] == pytest.approx(y[~held].mean())


def test_spearman_is_scipys_and_nan_when_undefined():
    assert spearman(np.array([1.0, 2, 3, 4]), np.array([10.0, 30, 20, 40])) == pytest.approx(0.8)
    assert np.isnan(spearman(np.array([1.0, 1, 1]), np.array([1.0, 2, 3])))


def test_model_file_of_another_version_is_refused(tmp_path):
    p = tmp_path / "m.json"
    p.write_text(json.dumps({"format": FORMAT, "version": VERSION + 1}))
    with pytest.raises(InputError, match=f"version {VERSION + 1}.*reads version {VERSION}"):
        load_model(p)
    p.write_text("{not json")
    with pytest.raises(InputError, match="not a JSON model file"):
        load_model(p)
    p.write_text(json.dumps({"format": "other"}))
    with pytest.raises(InputError, match=f"not a {FORMAT} file"):
        load_model(p)


def test_furnished_variant_belongs_to_its_building():
    assert building_of("office_a_furnitures") == "office_a"
    assert building_of("lab_ipa") == "lab_ipa"


def test_conformal_margin_is_the_rank_ceil_n_plus_1_times_level():
    # 9 scores at level 0.8: rank ceil(10 * 0.8) = 8, the 8th smallest
    scores = np.array([0.5, -0.3, 0.1, 0.9, -0.1, 0.2, 0.4, 0.0, 0.7])
    assert conformal_margin(scores, 0.8) == 0.7
    assert conformal_margin(np.array([0.3, -0.2]), 0.8) == 0.3  # rank 3 > 2: the largest
    assert conformal_margin(np.array([]), 0.8) == 0.0


def test_calibrated_intervals_hold_about_80_percent_of_held_out_worlds():
    # log error = a linear law plus noise wider than the trees can see in 40 buildings: their
    # own 10-90 % intervals hold too few held-out worlds; the conformal ones hold ~80 %
    rng = np.random.default_rng(7)
    area = rng.uniform(100, 3000, 80)
    y = 0.05 * np.exp(area / 2000 + rng.normal(0, 0.4, 80))
    s = leave_one_building_out(_dataset(area, rng.normal(size=80), y)).scores()["trees"]
    assert s["interval_coverage"] < 0.75
    assert 0.72 <= s["calibrated_interval_coverage"] <= 0.9


def test_prediction_interval_is_widened_by_the_stored_margin_on_the_log_scale():
    def stump(v):  # one constant tree: what export_gbr writes for a model predicting v
        return {"init": v, "learning_rate": 1.0, "trees": [
            {"feature": [-2], "threshold": [0.0], "left": [-1], "right": [-1], "value": [0.0]}
        ]}  # fmt: skip

    spec = {
        "transform": "log",
        "linear": {"mean": [0.0], "scale": [1.0], "coef": [0.0], "intercept": np.log(0.1)},
        "quantiles": {
            "0.1": stump(np.log(0.08)),
            "0.5": stump(np.log(0.1)),
            "0.9": stump(np.log(0.12)),
        },  # fmt: skip
    }
    x, names = np.array([1.0]), ["free_area_m2"]
    raw = _target(spec, x, names, "m")
    assert (raw.low, raw.median, raw.high) == pytest.approx((0.08, 0.1, 0.12))
    wide = _target({**spec, "interval_margin": 0.5}, x, names, "m")
    assert (wide.low, wide.high) == pytest.approx((0.08 * np.exp(-0.5), 0.12 * np.exp(0.5)))
    narrow = _target({**spec, "interval_margin": -1.0}, x, names, "m")
    assert narrow.low == narrow.median == narrow.high == pytest.approx(0.1)  # never past it
