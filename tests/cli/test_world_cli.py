"""`mapqual world info|list`: facts as text and JSON, one-line errors with exit code 2."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

WORLDS = Path(__file__).resolve().parents[2] / "worlds"


@pytest.fixture
def plan(tmp_path) -> Path:
    img = np.zeros((40, 80), dtype=np.uint8)
    img[1:-1, 1:-1] = 255  # 78 x 38 free pixels
    path = tmp_path / "plan.png"
    Image.fromarray(img).save(path)
    return path


def test_info_json_on_a_bundled_yaml_needs_no_flags(run):
    code, out, err = run("world", "info", WORLDS / "bormann" / "office_a.yaml", "--json")
    assert code == 0, err
    facts = json.loads(out)
    w, h = Image.open(WORLDS / "bormann" / "no_furniture" / "office_a.png").size
    assert facts["width_m"] == pytest.approx(w * 0.05)
    assert facts["height_m"] == pytest.approx(h * 0.05)
    assert facts["resolution"] == 0.05
    assert len(facts["start_pose"]) == 3 and facts["free_area_m2"] > 0
    assert facts["n_rooms"] > 0


def test_info_on_an_image_with_resolution(run, plan):
    code, out, err = run("world", "info", plan, "--resolution", "0.1", "--json")
    assert code == 0, err
    facts = json.loads(out)
    assert facts["width_m"] == pytest.approx(8.0) and facts["height_m"] == pytest.approx(4.0)
    assert facts["free_area_m2"] == pytest.approx(78 * 38 * 0.01)
    code, out, _ = run("world", "info", plan, "--resolution", "0.1")
    assert code == 0 and "free area: 29.6 m^2" in out and "start pose" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--resolution", "5"], "outside (0.005, 1]"),
        ([], "needs its resolution"),
        (["--resolution", "0.1", "--max-pixels", "100"], "more than the limit"),
    ],
)
def test_info_errors_are_one_line_with_exit_2(run, plan, args, message):
    code, out, err = run("world", "info", plan, *args)
    assert code == 2
    assert message in err and err.count("\n") == 1 and err.startswith("mapqual: error: ")


def test_info_on_a_missing_or_broken_file(run, tmp_path):
    code, _, err = run("world", "info", tmp_path / "nope.yaml")
    assert code == 2 and "no such file" in err and err.count("\n") == 1
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    code, _, err = run("world", "info", bad, "--resolution", "0.05")
    assert code == 2 and "not a readable image" in err and err.count("\n") == 1
    cramped = tmp_path / "cramped.png"
    img = np.zeros((20, 20), dtype=np.uint8)
    img[5:15, 5:10] = 255  # 0.25 m wide at 0.05 m/px: no room for the 0.4 m robot
    Image.fromarray(img).save(cramped)
    code, _, err = run("world", "info", cramped, "--resolution", "0.05")
    assert code == 2 and "no free space wide enough" in err and err.count("\n") == 1


def test_list_a_folder(run, tmp_path, plan):
    (tmp_path / "plan.yaml").write_text("image: plan.png\nresolution: 0.1\n")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "other.yaml").write_text("image: ../plan.png\nresolution: 0.05\n")
    # sub/other.yaml reaches out of its folder: refused unless --allow-outside
    code, out, err = run("world", "list", tmp_path, "--json")
    assert code == 2 and "`image` '../plan.png' lies outside" in err
    code, out, err = run("world", "list", tmp_path, "--json", "--allow-outside")
    assert code == 0, err
    rows = json.loads(out)
    assert [r["name"] for r in rows] == ["plan", "other"]
    assert rows[1]["width_m"] == pytest.approx(4.0)
    code, out, _ = run("world", "list", tmp_path, "--allow-outside")
    assert code == 0 and "2 worlds in" in out and "plan" in out
    code, _, err = run("world", "list", tmp_path / "missing")
    assert code == 2 and "no such folder" in err


def test_every_input_form_through_the_cli(run, plan, tmp_path):
    (tmp_path / "plan.yaml").write_text("image: plan.png\nresolution: 0.1\norigin: [1, 2, 0]\n")
    (tmp_path / "plan.world").write_text(
        'floorplan ( bitmap "plan.png" size [8 4 1] pose [0 0 0 0] )\n'
        "robot ( pose [1.0 0.5 0 180] )\n"
    )
    expected = {
        "plan.png": ([0.0, 0.0], None),
        "plan.yaml": ([1.0, 2.0], None),
        "plan.world": ([-4.0, -2.0], [1.0, 0.5, -3.141593]),
    }
    for name, (origin, start) in expected.items():
        extra = ["--resolution", "0.1"] if name.endswith(".png") else []
        code, out, err = run("world", "info", tmp_path / name, *extra, "--json")
        assert code == 0, err
        facts = json.loads(out)
        assert facts["origin"] == pytest.approx(origin)
        assert facts["width_m"] == pytest.approx(8.0) and facts["height_m"] == pytest.approx(4.0)
        if start is not None:
            assert facts["start_pose"] == pytest.approx(start)


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("bad.yaml", "image: plan.png\nresolution: [\n", "not valid YAML"),
        ("bad.yaml", "image: plan.png\n", "no `resolution:`"),
        ("bad.world", 'floorplan ( bitmap "plan.png" size [8 1 1] )\n', "non-square"),
        ("bad.world", 'floorplan ( bitmap "nope.png" size [8 4 1] )\n', "no such file"),
        ("bad.world", 'floorplan ( bitmap "plan.png" size [8 4 1] pose [0 0 0 30] )\n', "90"),
    ],
)
def test_yaml_and_stage_errors_through_the_cli(run, plan, tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    code, _, err = run("world", "info", tmp_path / name)
    assert code == 2 and message in err and err.count("\n") == 1


def test_generate_writes_a_world_that_info_reads(run, tmp_path):
    code, out, err = run(
        "world", "generate", "warehouse", "-o", tmp_path, "--width", "60", "--height", "40"
    )
    assert code == 0, err
    yaml_path = tmp_path / "warehouse_60x40_s1.yaml"
    assert yaml_path.is_file() and (tmp_path / "warehouse_60x40_s1.png").is_file()
    code, out, err = run("world", "info", yaml_path, "--json")
    assert code == 0, err
    facts = json.loads(out)
    assert facts["width_m"] == pytest.approx(60.0) and facts["n_free_regions"] == 1


def test_generate_refuses_an_unknown_kind_in_one_line(run, tmp_path):
    code, out, err = run("world", "generate", "castle", "-o", tmp_path)
    assert code == 2
    assert "unknown building kind" in err and len(err.strip().splitlines()) == 1
