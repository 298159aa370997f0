"""RunParams: stored JSON unchanged, old runs' params readable, the footprint set once, light."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from worker.errors import InputError
from worker.explore.flat_params import GROUPS
from worker.explore.params import CostmapParams, ExploreParams
from worker.run_params import RunParams, run_params_schema
from worker.sim.params import SimParams

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "office_a" / "summary.json"
BEFORE_GROUPS = Path(__file__).resolve().parent / "data" / "run_params_before_groups.json"


# parameters added after examples/office_a was written: exploration constants that became
# settings (issue 16), rbpf's sub-stepped motion noise for sparse logs (issue 17), and
# exploration settings of issue 18
SETTINGS_SINCE_EXAMPLE = {
    "explore": [
        "back_out_check_time",
        "back_out_gain",
        "back_out_lookahead",
        "back_out_speed_ratio",
        "blacklist_arrivals",
        "closed_gap_radius",
        "closed_gap_reopens",
        "coverage_period",
        "door_align",
        "door_angle",
        "door_engage_width",
        "door_lookahead",
        "door_margin",
        "door_patience",
        "door_speed",
        "door_wall_min",
        "door_width",
        "goal_search_extra",
        "incomplete_area",
        "incomplete_cell_loss",
        "incomplete_width",
        "local_raytrace",
        "look_fov_margin",
        "look_through_min_area",
        "look_through_radius",
        "narrow_margin",
        "no_frontier_time",
        "noisy_door_align",
        "noisy_obstacle_min_prob",
        "obstacle_layer",
        "obstacle_min_prob",
        "obstacle_range",
        "progress_step",
        "raytrace_range",
        "recovery_delay",
        "retrace_lookahead",
        "retrace_max_heading_error",
        "retrace_min_points",
        "retrace_points",
        "retrace_tolerance",
        "safety_median_beams",
        "same_goal_distance",
        "sealed_pocket_cells",
        "sight_candidates",
        "snapshot_change",
        "snapshot_holds",
        "snapshot_holds_area",
        "snapshot_measure",
        "snapshot_tolerance",
        "squeeze_margin",
        "stuck_distance",
        "trail_cap",
        "trail_spacing",
        "trail_trim",
        "trap_reach",
        "unwedge_time",
    ],
    "slam": ["coarse_levels", "coarse_skip", "motion_substep", "motion_substep_angle"],
}


def _flat(explore: dict) -> dict:
    """The nested `explore` section as the flat mapping of before the groups (key order aside)."""
    out = {}
    for key, value in explore.items():
        out.update(value if key in GROUPS else {key: value})
    return out


def test_stored_params_of_the_old_code_round_trip_byte_for_byte():
    # examples/office_a/summary.json was written by the hand-written converter (before
    # pydantic and before the exploration's groups): its params (rbpf, time limit 300 s,
    # footprint 0.4 m and its half 0.2 m, GMapping's defaults) come back with the same values
    # and number formatting; the exploration's flat keys each under its group
    text = EXAMPLE.read_text()
    stored = json.loads(text)["params"]
    assert stored["explore"]["time_limit"] == 300.0 and stored["explore"]["footprint_half_m"] == 0.2
    params = RunParams.from_json(stored)
    assert params.explore.time_limit == 300.0 and params.sim.footprint == 0.4
    assert params.explore.costmap.footprint_half_m == 0.2
    again = params.to_json()
    assert RunParams.from_json(again) == params  # the nested JSON reads back too
    assert again["explore"]["stop"]["snapshot_period"] == stored["explore"]["snapshot_period"]
    # the settings that were constants in the code when the example was written come on top,
    # each under its name; everything else is as stored, keys, order and numbers
    sections = [k for k in stored if isinstance(stored[k], dict)]
    again_flat = {**again, "explore": _flat(again["explore"])}
    added = {k: sorted(set(again_flat[k]) - set(stored[k])) for k in sections}
    assert {k: v for k, v in added.items() if v} == SETTINGS_SINCE_EXAMPLE
    kept = {
        k: {n: again_flat[k][n] for n in stored[k]} if k in sections else again_flat[k]
        for k in stored
    }
    assert json.dumps(kept) == json.dumps(stored)
    # and as summary.json holds them, one level down
    assert '"params": ' + json.dumps(kept, indent=2).replace("\n", "\n  ") in text
    defaults = RunParams().to_json()
    # issue 51's real-time emulation: a section of its own, null (instant SLAM) by default
    assert list(defaults) == ["algorithm", "sim", "slam", "explore", "eval", "realtime"]
    assert defaults["realtime"] is None
    assert list(defaults["explore"]["costmap"])[:2] == ["footprint_half_m", "footprint_padding"]
    assert json.dumps(defaults["sim"]["laser"]) == (
        '{"n_beams": 541, "angle_min": -2.356194490192345, '
        '"angle_increment": 0.008726646259971648, "range_max": 30.0, "range_min": 0.0}'
    )


# settings added after run_params_before_groups.json was written, with their defaults: a stored
# run without them reads them as these (issue 52: the snapshot rule's waits by known area)
SETTINGS_SINCE_GROUPS = {"snapshot_holds_area": 2500.0}


def test_params_stored_before_the_groups_load_to_the_same_run():
    # written by main's code before the groups (see the file's _note): every stored key
    # comes back under its group with its value, the run's settings are the ones it asked for
    data = json.loads(BEFORE_GROUPS.read_text())
    default = RunParams.from_json(data["default"])
    assert default == RunParams()
    since = SETTINGS_SINCE_GROUPS
    assert _flat(default.to_json()["explore"]) == data["default"]["explore"] | since
    custom = RunParams.from_json(data["custom"])
    e = custom.explore
    assert custom.algorithm == "odometry" and custom.sim.footprint == 0.5
    assert e.costmap.footprint_half_m == 0.25 and e.time_limit == 600.0
    assert e.doors.door_align is True and e.recovery.trail_cap == 150
    assert e.dwa.max_vel_x == 0.5 and e.stop.snapshot_measure == "mse"
    assert e.planner.planner_margin == 0.12 and e.safety.safety_median_beams == 5
    assert e.frontiers.look_through_radius == 0.0 and e.costmap.obstacle_min_prob == 0.2
    assert e.progress_period == 2.0
    assert _flat(custom.to_json()["explore"]) == data["custom"]["explore"] | since
    # the submitted flat overrides (a job of before the groups) give the same run as well
    assert RunParams.from_json(data["custom_input"]) == custom
    assert RunParams.from_json(custom.to_json()) == custom


def test_the_footprint_is_set_once_and_the_exploration_follows():
    p = RunParams.from_json({"sim": {"footprint": 0.5}})
    assert p.sim.footprint == 0.5 and p.explore.costmap.footprint_half_m == 0.25
    assert p.to_json()["explore"]["costmap"]["footprint_half_m"] == 0.25
    assert RunParams.from_json(p.to_json()) == p  # a stored run of it reads back
    assert RunParams().explore.costmap.footprint_half_m == 0.2
    for explore in ({"footprint_half_m": 0.3}, {"costmap": {"footprint_half_m": 0.3}}):
        with pytest.raises(InputError, match="set the robot's size with sim.footprint"):
            RunParams.from_json({"explore": explore})
    with pytest.raises(InputError, match="footprint must be > 0"):
        RunParams.from_json({"sim": {"footprint": 0.0}})
    # built in Python: the exploration is given the robot's size, or the run is refused
    sim = SimParams(footprint=0.5)
    with pytest.raises(InputError, match="set the robot's size with sim.footprint"):
        RunParams(sim=sim)
    with pytest.raises(InputError, match="set the robot's size with sim.footprint"):
        RunParams(explore=ExploreParams(costmap=CostmapParams(footprint_half_m=0.3)))
    assert RunParams(sim=sim, explore=ExploreParams().with_footprint(0.5)) == p


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"algorithm": "ekf"}, "algorithm: must be one of 'rbpf', 'odometry', 'oracle'"),
        ({"slam": {"particles": "40"}}, "slam.particles must be an integer"),
        ({"sim": {"odom_error": [0.1, 0.1]}}, "sim.odom_error must have 3 elements"),
        ({"sim": {"laser": {"n_beams": 0}}}, "sim.laser: LaserSpec.n_beams must be >= 1"),
        ({"eval": {"b": {"z": float("inf")}}}, "eval.b.z must be a finite number"),
        ({"explore": {"time_limit": -5}}, "explore: exploration parameters must be positive"),
        ({"eval": {"bb": {}}}, "unknown parameter eval.bb (valid: a, b, max_gap, sm)"),
        ({"explore": {"trail_cap": 5}}, "explore.recovery: exploration parameter trail_trim"),
        ({"explore": {"door_allign": True}}, "unknown parameter explore.door_allign (valid: "),
        ([1, 2], "parameters must be a mapping"),
    ],
)
def test_bad_params_are_one_line_input_errors_naming_the_key(data, message):
    with pytest.raises(InputError) as err:
        RunParams.from_json(data)
    assert str(err.value).startswith(message) and "\n" not in str(err.value)


def test_the_schema_is_inline_and_every_key_optional():
    schema = run_params_schema()
    assert "$defs" not in json.dumps(schema) and "$ref" not in json.dumps(schema)
    assert schema["properties"]["algorithm"]["enum"] == [
        "rbpf",
        "odometry",
        "oracle",
        "graph",
        "external",
    ]
    assert schema["properties"]["sim"]["properties"]["odom_model"]["enum"] == ["stage", "gaussian"]
    assert "required" not in json.dumps(schema)


def test_params_import_no_numba():
    code = (
        "import sys, worker.run_params, worker.param_io, worker.slam.registry;"
        "worker.run_params.RunParams.from_json({'slam': {'particles': 3}});"
        "worker.run_params.run_params_schema();"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'llvmlite')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
