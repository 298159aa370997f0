"""The Stage parser on nesting: a world as Stage writes it is read, blocks nested past the
limit are one InputError naming the line (never a RecursionError)."""

from __future__ import annotations

from pathlib import Path

import pytest

from worker.errors import InputError
from worker.world.stage import MAX_NESTING, parse_entities, read_stage_world

WORLD = """
define block model ( size [0.5 0.5 0.5] gui_nose 0 )
floorplan ( name "cave" bitmap "cave.png" size [16 16 0.8] pose [0 0 0 0] )
pioneer2dx ( name "r0" pose [ -7 -7 0 45 ] sicklaser ( pose [ 0 0 0 0 ] ctrl "lasernoise" ) )
"""


def _nested(depth: int) -> str:
    return 'floorplan ( bitmap "a.png" size [1 1 1]\n' + "m (\n" * (depth - 1) + ")\n" * depth


def test_a_stage_world_with_a_nested_sensor_is_read(tmp_path: Path):
    path = tmp_path / "cave.world"
    path.write_text(WORLD)
    m = read_stage_world(path)
    assert m.size == (16.0, 16.0) and m.robot_pose is not None
    assert m.robot_pose[:2] == (-7.0, -7.0)


def test_nesting_up_to_the_limit_is_read_and_past_it_refused(tmp_path: Path):
    top = parse_entities(_nested(MAX_NESTING), tmp_path / "ok.world")[0]
    depth = 1
    while top.children:
        top, depth = top.children[0], depth + 1
    assert depth == MAX_NESTING
    with pytest.raises(InputError, match=f"nested more than {MAX_NESTING} deep") as err:
        parse_entities(_nested(MAX_NESTING + 1), tmp_path / "deep.world")
    assert f"deep.world:{MAX_NESTING + 1}:" in str(err.value)


def test_an_800_kb_world_of_nested_blocks_is_an_input_error(tmp_path: Path):
    text = "floorplan (\n" + "block ( " * 100_000 + ")" * 100_000 + "\n)\n"
    assert len(text) > 800_000
    with pytest.raises(InputError, match="nested more than"):
        parse_entities(text, tmp_path / "bomb.world")
