"""Experiment expansion: seeds, lists, groups, overrides, run keys, the bundled thesis set."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from worker.batch.experiment import (
    build_groups,
    expand,
    load_experiment,
    parse_seeds,
    resolve_worlds,
    variant_of,
)
from worker.errors import InputError
from worker.run_params import RunParams


def _world(folder, name, door=True):
    img = np.full((60, 100), 255, np.uint8)
    img[[0, -1], :] = 0
    img[:, [0, -1]] = 0
    img[:, 50] = 0
    if door:
        img[20:40, 50] = 255
    Image.fromarray(img).save(folder / f"{name}.png")
    path = folder / f"{name}.yaml"
    path.write_text(f"image: {name}.png\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n")
    return path


def test_parse_seeds_ranges_lists_and_errors():
    assert parse_seeds("1-4") == (1, 2, 3, 4)
    assert parse_seeds("3, 1,3,7-8") == (3, 1, 7, 8)
    for bad in ("4-1", "a", "1-", "", "1-200000"):
        with pytest.raises(InputError):
            parse_seeds(bad)


def test_variant_of_bormann_names():
    assert variant_of("office_a_furnitures") == ("office_a", "furniture")
    assert variant_of("lab_a_scan_furnitures") == ("lab_a_scan", "furniture")
    assert variant_of("lab_a_scan") == ("lab_a_scan", "no_furniture")


def test_product_order_keys_and_parameters(tmp_path):
    a, b = _world(tmp_path, "a"), _world(tmp_path, "b_furnitures", door=False)
    over = {
        "worlds": [str(a), str(b)],
        "runs": 2,
        "slam": "odometry,oracle",
        "laser_noise": "0,0.1",
    }
    groups = build_groups({}, None, over, {"explore": {"time_limit": 30.0}})
    specs, worlds = expand(groups)
    assert len(specs) == 2 * 2 * 2 * 2 and len(worlds) == 2
    assert len({s.key for s in specs}) == len(specs)
    # seed-major: the first runs span every world
    assert [(s.seed, s.world) for s in specs[:8]] == [(1, "a")] * 4 + [(1, "b_furnitures")] * 4
    for s in specs:
        p = RunParams.from_json(s.params)
        assert (p.algorithm, p.sim.laser_noise_sigma) == (s.slam, s.noise)
        assert p.explore.time_limit == 30.0
    assert {(s.base, s.variant) for s in specs} == {("a", "no_furniture"), ("b", "furniture")}
    # keys are stable and depend on the seed, the parameters and the world's content
    again, _ = expand(build_groups({}, None, over, {"explore": {"time_limit": 30.0}}))
    assert [s.key for s in again] == [s.key for s in specs]
    other, _ = expand(build_groups({}, None, over, {"explore": {"time_limit": 31.0}}))
    assert not {s.key for s in other} & {s.key for s in specs}
    _world(tmp_path, "a", door=False)  # same file name, different floorplan
    changed, _ = expand(build_groups({}, None, over, {"explore": {"time_limit": 30.0}}))
    assert {s.key for s in changed if s.world == "a"}.isdisjoint(s.key for s in specs)


def test_experiment_file_groups_deduplicate_and_options_override(tmp_path):
    _world(tmp_path, "a"), _world(tmp_path, "b")
    exp = tmp_path / "exp.yaml"
    exp.write_text(
        "name: demo\nruns: 3\nslam: [odometry]\nparams: {explore: {time_limit: 40}}\n"
        "groups:\n  - {worlds: [a.yaml, b.yaml]}\n"
        "  - {worlds: [a.yaml], laser_noise: [0, 0.3], seeds: 1-2}\n"
    )
    raw, base = load_experiment(str(exp))
    specs, _ = expand(build_groups(raw, base, {}, {}))
    # 2 worlds x 3 seeds, plus a at noise 0.3 for seeds 1-2 (a at noise 0 is already there)
    assert len(specs) == 6 + 2
    assert {s.noise for s in specs if s.world == "a"} == {0.0, 0.3}
    assert all(RunParams.from_json(s.params).explore.time_limit == 40 for s in specs)
    fewer, _ = expand(build_groups(raw, base, {"runs": 1}, {}))
    assert sorted((s.world, s.noise, s.seed) for s in fewer) == [
        ("a", 0.0, 1), ("a", 0.3, 1), ("b", 0.0, 1)
    ]  # fmt: skip


@pytest.mark.parametrize(
    ("raw", "message"),
    [
        ({"worlds": ["a.yaml"], "colour": 1}, "unknown key 'colour'"),
        ({"worlds": ["a.yaml"], "slam": ["gmapping"]}, "slam"),
        ({"worlds": ["a.yaml"], "laser_noise": [-0.1]}, "laser noise"),
        ({"worlds": ["a.yaml"], "runs": 0}, "runs must be"),
        ({"worlds": ["a.yaml"], "runs": 2, "seeds": "1-2"}, "not both"),
        ({"worlds": ["missing.yaml"]}, "no such world"),
        ({"worlds": ["a.png"]}, "give an image a map_server YAML"),
        ({"worlds": ["a.yaml"], "params": {"sim": {"bogus": 1}}}, "sim.bogus"),
        ({}, "no worlds given"),
    ],
)
def test_bad_experiments_are_one_line_errors(tmp_path, raw, message):
    _world(tmp_path, "a")
    with pytest.raises(InputError, match=message):
        expand(build_groups(raw, tmp_path, {}, {}))


def test_folders_expand_to_their_floorplans(tmp_path):
    (tmp_path / "sub").mkdir()
    _world(tmp_path / "sub", "x"), _world(tmp_path / "sub", "y")
    assert [p.stem for p in resolve_worlds([tmp_path / "sub"])] == ["x", "y"]
    assert resolve_worlds([tmp_path / "sub", tmp_path / "sub" / "x.yaml"])[-1].stem == "y"
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no floorplan"):
        resolve_worlds([tmp_path / "empty"])


def test_thesis_experiment_is_both_variants_ten_runs_and_a_noise_sweep():
    raw, base = load_experiment("thesis")
    groups = build_groups(raw, base, {}, {})
    worlds = {p.stem for g in groups for p in g.worlds}
    assert len(worlds) == 32 and sum(w.endswith("_furnitures") for w in worlds) == 16
    assert all(g.seeds == tuple(range(1, 11)) and g.slam == ("rbpf",) for g in groups)
    sweeps = [g for g in groups if len(g.laser_noise) > 1]
    assert len(sweeps) == 1 and sweeps[0].laser_noise == (0.0, 0.1, 0.3)
    assert len(sweeps[0].worlds) == 2
    # without loading 32 floorplans: 32 x 10 runs, plus 2 worlds x 2 more noise levels x 10
    n = len({(p, s, n) for g in groups for p in g.worlds for s in g.seeds for n in g.laser_noise})
    assert n == 32 * 10 + 2 * 2 * 10
