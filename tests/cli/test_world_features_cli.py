"""`mapqual world info` shows the floorplan features (issue 22), in text and JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from worker.world.features import FEATURE_DOCS

WORLDS = Path(__file__).resolve().parents[2] / "worlds"


def test_info_shows_every_feature_with_its_unit(run):
    code, out, err = run("world", "info", WORLDS / "bormann" / "lab_ipa.yaml", "--json")
    assert code == 0, err
    info = json.loads(out)
    assert set(info["features"]) == set(FEATURE_DOCS) and info["features_error"] is None
    # the rooms come from the YAML's gt_segmentation: the same count as the facts' own
    assert info["features"]["rooms_from"] == "segmentation"
    assert info["features"]["n_rooms"] == info["n_rooms"]
    assert info["features"]["free_area_m2"] == info["largest_region_area_m2"]
    code, out, err = run("world", "info", WORLDS / "bormann" / "lab_ipa.yaml")
    assert code == 0 and "openness_m2" in out and "m^2" in out


def test_info_says_why_a_plan_has_no_features(run, tmp_path):
    Image.fromarray(np.full((30, 30), 255, np.uint8)).save(tmp_path / "open.png")
    code, out, err = run("world", "info", tmp_path / "open.png", "--resolution", "0.05")
    assert code == 0, err
    assert "features: none" in out and "no enclosed free space" in out
