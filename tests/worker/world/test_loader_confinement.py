"""A floorplan's references (`image:`, `segmentation:`, Stage `bitmap`) may not leave its folder:
absolute paths, `../` and symlinks pointing out are refused with one line, unless allowed; the
CLI says so with exit code 2 and takes `--allow-outside`."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from mapqual.cli import main
from worker.errors import InputError
from worker.world import load_world


def _plan(path: Path) -> Path:
    img = np.zeros((40, 60), dtype=np.uint8)
    img[2:-2, 2:-2] = 255
    Image.fromarray(img).save(path)
    return path


def _segmentation(path: Path) -> Path:
    img = np.zeros((40, 60), dtype=np.uint8)
    img[2:-2, 2:29] = 255
    img[2:-2, 31:-2] = 255
    Image.fromarray(img).save(path)
    return path


@pytest.fixture
def tree(tmp_path) -> dict[str, Path]:
    """`secret/` holds images the floorplan in `maps/` must not reach; `maps/sub/` is inside."""
    (tmp_path / "secret").mkdir()
    (tmp_path / "maps" / "sub").mkdir(parents=True)
    return {
        "maps": tmp_path / "maps",
        "secret_plan": _plan(tmp_path / "secret" / "map.png"),
        "secret_seg": _segmentation(tmp_path / "secret" / "seg.png"),
        "inside_plan": _plan(tmp_path / "maps" / "sub" / "plan.png"),
        "inside_seg": _segmentation(tmp_path / "maps" / "seg.png"),
    }


def _escapes(tree, target: Path) -> dict[str, str]:
    """Three ways to name `target` from maps/: absolute, ../, and a symlink inside pointing out."""
    link = tree["maps"] / f"link_{target.name}"
    link.symlink_to(target)
    return {"absolute": str(target), "dotdot": f"../secret/{target.name}", "symlink": link.name}


def _yaml(tree, image: str, segmentation: str | None = None) -> Path:
    path = tree["maps"] / "m.yaml"
    text = f"image: {image}\nresolution: 0.05\norigin: [0, 0, 0]\n"
    if segmentation is not None:
        text += f"segmentation: {segmentation}\n"
    path.write_text(text)
    return path


def _stage(tree, bitmap: str) -> Path:
    path = tree["maps"] / "m.world"
    path.write_text(f'floorplan ( bitmap "{bitmap}" size [3.0 2.0 0.5] pose [0 0 0 0] )\n')
    return path


def _describe(tree, key: str, value: str) -> Path:
    if key == "image":
        return _yaml(tree, value)
    if key == "segmentation":
        return _yaml(tree, "sub/plan.png", value)
    return _stage(tree, value)


@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink"])
@pytest.mark.parametrize("key", ["image", "segmentation", "bitmap"])
def test_a_reference_out_of_the_folder_is_refused_in_one_line_unless_allowed(tree, key, how):
    target = tree["secret_seg"] if key == "segmentation" else tree["secret_plan"]
    value = _escapes(tree, target)[how]
    path = _describe(tree, key, value)
    with pytest.raises(InputError) as err:
        load_world(path)
    message = str(err.value)
    assert "\n" not in message
    assert f"`{key}`" in message and repr(value) in message and "outside" in message
    world = load_world(path, allow_outside=True)
    assert world.occ.shape == (40, 60)
    if key == "segmentation":
        assert world.facts.n_rooms == 2


@pytest.mark.parametrize("key", ["image", "segmentation", "bitmap"])
def test_references_inside_the_folder_still_load(tree, key):
    value = {"image": "sub/plan.png", "segmentation": "seg.png", "bitmap": "./sub/plan.png"}[key]
    world = load_world(_describe(tree, key, value))
    assert world.occ.shape == (40, 60)
    # a symlink that stays inside the folder is fine too
    (tree["maps"] / "alias.png").symlink_to(tree["inside_plan"])
    assert load_world(_yaml(tree, "alias.png")).occ.shape == (40, 60)


def _cli(monkeypatch, capsys, *argv) -> tuple[int, str, str]:
    monkeypatch.setattr(sys, "argv", ["mapqual", *map(str, argv)])
    try:
        main()
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("command", [["world", "info"], ["simulate", "--duration", "1", "-o"]])
def test_the_cli_exits_2_with_one_line_and_takes_allow_outside(
    tree, monkeypatch, capsys, tmp_path, command
):
    path = _yaml(tree, "../secret/map.png")
    args = [*command, tmp_path / "sim"] if command[0] == "simulate" else command
    code, out, err = _cli(monkeypatch, capsys, *args, path)
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "`image` '../secret/map.png'" in err and "outside" in err
    if command[0] == "world":  # (a simulation is not needed to see the flag work)
        code, out, err = _cli(monkeypatch, capsys, *args, path, "--allow-outside")
        assert code == 0 and "60 x 40 px" in out, err


def test_every_cli_command_that_loads_a_world_has_allow_outside(monkeypatch, capsys):
    for command in (["world", "info"], ["world", "list"], ["simulate"], ["run"], ["batch"]):
        code, out, _ = _cli(monkeypatch, capsys, *command, "--help")
        assert code == 0 and "--allow-outside" in out, command
