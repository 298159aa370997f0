"""An external program's runs are labelled external:NAME (summary, batch specs and tables), so
two programs in one batch get rows of their own; other algorithms keep their plain names."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from worker.batch.experiment import build_groups, expand
from worker.batch.state import record_of
from worker.batch.tables import success_rows, write_tables
from worker.errors import InputError
from worker.run_params import RunParams
from worker.slam import registry
from worker.slam.external.params import ExternalSlamParams
from worker.slam.params import SlamParams


def test_the_label_names_the_program_and_parses_back():
    slam = SlamParams(external=ExternalSlamParams(name="mine", command=("prog",)))
    assert registry.label("external", slam) == "external:mine"
    assert registry.label("rbpf", SlamParams()) == "rbpf"
    assert registry.label("odometry") == "odometry"
    assert registry.parse_label("external:mine") == ("external", "mine")
    assert registry.parse_label("graph") == ("graph", None)
    # the label fits the database's slam column of 40 characters
    ExternalSlamParams(name="a" * 31)
    with pytest.raises(InputError, match="longer than 31 letters"):
        ExternalSlamParams(name="a" * 32)


def _world(folder):
    img = np.full((60, 100), 255, np.uint8)
    img[[0, -1], :] = img[:, [0, -1]] = 0
    Image.fromarray(img).save(folder / "box.png")
    path = folder / "box.yaml"
    path.write_text("image: box.png\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n")
    return path


def _program(name: str) -> dict:
    return {"slam": {"external": {"name": name, "command": ["/bin/true", name]}}}


def test_two_programs_in_one_batch_have_rows_of_their_own(tmp_path):
    world = str(_world(tmp_path))
    raw = {
        "worlds": [world], "seeds": "1-2",
        "groups": [
            {"slam": ["external"], "params": _program("alpha")},
            {"slam": ["external"], "params": _program("beta")},
            {"slam": ["rbpf"]},
        ],
    }  # fmt: skip
    specs, _ = expand(build_groups(raw, tmp_path, {}, {}))
    assert sorted({s.slam for s in specs}) == ["external:alpha", "external:beta", "rbpf"]
    for s in specs:  # the params still name the algorithm the worker runs
        want = "rbpf" if s.slam == "rbpf" else "external"
        assert RunParams.from_json(s.params).algorithm == want
    records = [record_of(s, summary=None, error="not run") for s in specs]
    rows = success_rows(records)
    assert [(r["slam"], r["runs"]) for r in rows] == [
        ("external:alpha", 2), ("external:beta", 2), ("rbpf", 2),
    ]  # fmt: skip
    paths = write_tables(records, tmp_path)
    runs_csv = paths["runs"].read_text()
    assert runs_csv.count("external:alpha") == 2 and runs_csv.count("external:beta") == 2
