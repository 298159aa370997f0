"""`mapqual predict` and `mapqual predict train`: the bundled model on a bundled plan, training
from real batch tables, one-line errors with exit code 2."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
from PIL import Image

from worker.predict.model import BUNDLED, FORMAT, VERSION

ROOT = Path(__file__).resolve().parents[2]
WORLDS = ROOT / "worlds"
TRAINING = ROOT / "data" / "training" / "bormann-rbpf-short" / "runs.csv"


def test_predict_a_bundled_plan_with_the_bundled_model(run):
    code, out, err = run("predict", WORLDS / "bormann" / "office_a.yaml", "--json")
    assert code == 0, err
    p = json.loads(out)
    for target in ("b_mean_t", "b_mean_r"):
        t = p[target]
        assert 0 < t["low"] <= t["median"] <= t["high"]
        assert len(t["drivers"]) == 3
    assert 0.0 <= p["success_probability"] <= 1.0
    assert p["features"]["rooms_from"] == "segmentation"
    code, out, err = run("predict", WORLDS / "bormann" / "office_a.yaml")
    assert code == 0 and "80 % interval" in out and "driver" in out


def test_a_model_of_another_version_is_one_line(run, tmp_path):
    model = json.loads(BUNDLED.read_text())
    model["version"] = VERSION + 1
    path = tmp_path / "old.json"
    path.write_text(json.dumps(model))
    code, out, err = run("predict", WORLDS / "bormann" / "office_a.yaml", "--model", path)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and f"version {VERSION + 1}" in err


def test_a_plan_with_no_enclosed_free_space_is_one_line(run, tmp_path):
    img = np.full((40, 40), 255, np.uint8)  # all free: nothing encloses it
    Image.fromarray(img).save(tmp_path / "open.png")
    code, out, err = run("predict", tmp_path / "open.png", "--resolution", "0.05")
    assert code == 2 and err.count("\n") == 1 and "no enclosed free space" in err


def test_unknown_slam_and_stray_options_are_one_line(run):
    code, _, err = run("predict", WORLDS / "bormann" / "office_a.yaml", "--slam", "nope")
    assert code == 2 and "no 'nope' part" in err and err.count("\n") == 1
    code, _, err = run("predict", "a.yaml", "b.yaml")
    assert code == 2 and "give one WORLD" in err


def test_train_on_the_committed_tables_of_three_buildings(run, tmp_path):
    keep = {"lab_a_scan", "lab_b_scan", "lab_ipa"}
    with open(TRAINING, newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if r["world"].replace("_furnitures", "") in keep]
    assert len(rows) >= 5
    batch = tmp_path / "batch"
    batch.mkdir()
    with open(batch / "runs.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    out = tmp_path / "model.json"
    code, text, err = run("predict", "train", batch, "-o", out, "--worlds", WORLDS)
    assert code == 0, err
    model = json.loads(out.read_text())
    assert (model["format"], model["version"]) == (FORMAT, VERSION)
    part = model["slam"]["rbpf"]
    assert part["worlds"] == len({r["world"] for r in rows}) and part["buildings"] == 3
    assert set(part["cv"]["b_mean_t"]) == {"trees", "linear", "mean", "free_area"}
    assert set(part["targets"]["b_mean_t"]["importances"]) == set(model["features"])
    code, text, err = run("predict", WORLDS / "bormann" / "lab_ipa.yaml", "--model", out)
    assert code == 0, err


def test_train_without_runs_csv_is_one_line(run, tmp_path):
    code, _, err = run("predict", "train", tmp_path, "-o", tmp_path / "m.json")
    assert code == 2 and "no runs.csv" in err and err.count("\n") == 1
