"""Bundled data sets: folders found, licence file and dataset.json read, worlds summarised as
load_world sees them (facts, fingerprint, occupancy), a bad file named instead of fatal."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
from PIL import Image

from worker.world import load_world
from worker.world.catalogue import default_worlds_dir
from worker.world.datasets import dataset_folders, folder_signature, load_dataset

WORLDS = Path(__file__).resolve().parents[3] / "worlds"
YAML = "image: {image}\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\nnegate: 0\n" \
    "occupied_thresh: 0.65\nfree_thresh: 0.196\n"  # fmt: skip


def write_plan(folder: Path, name: str, w: int = 60, h: int = 40) -> Path:
    """A walled room of w x h px (one wall across, with a door) as a YAML and its PNG."""
    img = np.full((h, w), 255, np.uint8)
    img[[0, -1], :] = img[:, [0, -1]] = 0
    img[:, w // 2] = 0
    img[h // 2 - 8 : h // 2 + 8, w // 2] = 255
    folder.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(folder / f"{name}.png")
    (folder / f"{name}.yaml").write_text(YAML.format(image=f"{name}.png"))
    return folder / f"{name}.yaml"


def test_a_folder_of_plans_is_a_data_set_with_its_licence(tmp_path):
    write_plan(tmp_path / "set_a", "room_b")
    write_plan(tmp_path / "set_a", "room_a", w=80)
    write_plan(tmp_path / "set_a" / "more", "room_a")  # the same stem one folder down
    (tmp_path / "set_a" / "LICENSE").write_text("MIT License\n")
    (tmp_path / "set_a" / "README.md").write_text("about\n")
    (tmp_path / "empty").mkdir()
    (tmp_path / ".hidden").mkdir()
    write_plan(tmp_path / ".hidden", "x")
    assert [p.name for p in dataset_folders(tmp_path)] == ["set_a"]
    d = load_dataset(tmp_path / "set_a")
    assert (d.name, d.title, d.licence, d.licence_file) == ("set_a", "set_a", None, "LICENSE")
    assert d.licence_text() == "MIT License\n"
    assert [w.name for w in d.worlds] == ["more/room_a", "room_a", "room_b"]
    w = d.world("room_a")
    full = load_world(tmp_path / "set_a" / "room_a.yaml")
    assert w.facts == full.facts and w.fingerprint == full.fingerprint()
    np.testing.assert_array_equal(w.occupancy(), full.occ)
    assert w.source_format == "yaml" and w.facts_dict()["warnings"] == []
    assert d.world("../set_a/room_a") is None and d.world("room_a.yaml") is None


def test_dataset_json_names_title_and_licence_and_a_bad_plan_is_reported(tmp_path):
    folder = tmp_path / "set"
    write_plan(folder, "good")
    (folder / "broken.yaml").write_text("image: missing.png\nresolution: 0.05\n")
    (folder / "SOURCE.md").write_text("# where from\n")
    meta = {"title": "  A   set ", "licence": "CC-BY 4.0", "licence_file": "SOURCE.md"}
    (folder / "dataset.json").write_text(json.dumps(meta))
    d = load_dataset(folder)
    assert (d.title, d.licence, d.licence_file) == ("A set", "CC-BY 4.0", "SOURCE.md")
    assert [w.name for w in d.worlds] == ["good"]
    (problem,) = d.problems
    assert problem.startswith("broken.yaml: ") and "missing.png" in problem
    # a licence_file outside the folder is not followed: the usual names are looked for
    (folder / "dataset.json").write_text(json.dumps({"licence_file": "../../etc/passwd"}))
    assert load_dataset(folder).licence_file == "SOURCE.md"


def test_the_signature_changes_with_any_file_of_the_folder(tmp_path):
    write_plan(tmp_path, "a")
    before = folder_signature(tmp_path)
    png = tmp_path / "a.png"
    st = png.stat()

    os.utime(png, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert folder_signature(tmp_path) != before


def test_the_bundled_data_sets_have_a_title_a_licence_and_their_plans():
    # read without loading a world: the folders, their dataset.json and licence files
    assert default_worlds_dir().resolve() == WORLDS
    names = [p.name for p in dataset_folders(WORLDS)]
    assert names == ["bormann", "schools"]
    for name, licence_file, words in (
        ("bormann", "SOURCE.md", "LGPL"),
        ("schools", "LICENSE", "MIT"),
    ):
        meta = json.loads((WORLDS / name / "dataset.json").read_text())
        assert meta["licence_file"] == licence_file and words in meta["licence"]
        assert words in (WORLDS / name / licence_file).read_text()
