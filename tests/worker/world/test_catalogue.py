"""The bundled Bormann catalogue: every YAML loads, with the pixel rule and the frame we promise."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from worker.world import load_world
from worker.world.catalogue import find_worlds

WORLDS = Path(__file__).resolve().parents[3] / "worlds"


def test_catalogue_lists_both_variants_of_every_bormann_map():
    paths = find_worlds(WORLDS)
    names = {p.stem for p in paths}
    images = sorted((WORLDS / "bormann" / "no_furniture").glob("*.png"))
    assert len(images) == 16
    for img in images:
        assert img.stem in names and f"{img.stem}_furnitures" in names
    assert (WORLDS / "bormann" / "SOURCE.md").read_text().count("LGPL") >= 1


@pytest.mark.parametrize("name", ["office_a", "lab_ipa_furnitures"])
def test_yaml_applies_the_grey_250_rule_in_the_map_server_frame(name):
    world = load_world(WORLDS / "bormann" / f"{name}.yaml")
    folder = "furniture" if name.endswith("_furnitures") else "no_furniture"
    rgb = np.asarray(Image.open(WORLDS / "bormann" / folder / f"{name}.png").convert("RGB"))
    grey = rgb.astype(float).mean(axis=2)
    np.testing.assert_array_equal(world.occ, np.flipud(grey < 250))
    h, w = grey.shape
    assert world.width_m == pytest.approx(w * 0.05) and world.height_m == pytest.approx(h * 0.05)
    assert world.facts.n_rooms is not None and world.facts.n_rooms > 3
    assert world.facts.main_region_enclosed
    assert world.warnings == ()
