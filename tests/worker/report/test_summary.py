"""The typed run summary: summary.json byte for byte as the json module wrote it, old files load."""

from __future__ import annotations

import json
import subprocess
import sys
from typing import get_args

import pytest
from pydantic import ValidationError

from tests.summaries import EXAMPLE, make_summary, relation, stats, summary_doc
from tests.worker.test_pipeline import two_rooms
from worker.report.folder import SUMMARY, write_report
from worker.report.summary import SCHEMA_VERSION, RunSummary, summary_json_schema


def _dumps(doc: dict) -> str:
    """How summary.json was written before it was typed (json.dumps of the dict)."""
    return json.dumps(doc, indent=2) + "\n"


def test_a_summary_json_of_the_untyped_code_reads_back_to_the_same_bytes():
    # examples/office_a/summary.json was written by the code before the model existed
    text = EXAMPLE.read_text()
    s = RunSummary.model_validate_json(text)
    assert s.to_json_text() == text
    assert s.schema_version == SCHEMA_VERSION == 1  # no key in the file: version 1
    assert s.relations["SM"].rotation.min == 6.522917410656248e-07  # float formatting kept
    assert s.timings.slam_wall_s == 52.23980639000547 and s.collision is None


def test_a_summary_from_before_the_stages_were_timed_apart_still_loads():
    doc = summary_doc()
    for key in ("simulation_wall_s", "slam_wall_s"):
        del doc["timings"][key]
    s = RunSummary.load(doc)
    assert s is not None and s.timings.slam_wall_s is None
    assert s.timings.wall_time_s == 68.72248093200051


def test_nothing_stored_is_no_summary_and_a_wrong_one_is_refused():
    assert RunSummary.load(None) is None and RunSummary.load({}) is None
    with pytest.raises(ValidationError, match="schema_version"):
        RunSummary.load(summary_doc(schema_version=2))
    with pytest.raises(ValidationError, match="extra"):
        RunSummary.load(summary_doc(flavour="vanilla"))
    with pytest.raises(ValidationError, match="outcome"):
        RunSummary.load(summary_doc(outcome="maybe"))
    doc = summary_doc()
    del doc["goals"]["total"]
    with pytest.raises(ValidationError, match="goals.total"):
        RunSummary.load(doc)


def test_relation_is_none_for_a_kind_not_evaluated_or_with_no_relation():
    s = make_summary(relations={"A": relation(stats(0.5, n=3)), "B": relation(stats(None, n=0))})
    assert s.relation("B") is None and s.relation("SM") is None
    assert s.relation("A").translation.mean == 0.5


def test_the_outcomes_and_reasons_are_the_exploration_loops():
    from worker.explore import loop
    from worker.status import RunOutcome, RunReason

    fields = RunSummary.model_fields
    assert fields["outcome"].annotation is RunOutcome is loop.Outcome
    assert fields["stop"].annotation is RunReason is loop.Reason
    assert get_args(fields["reason"].annotation) == (RunReason, type(None))


def test_stored_outcomes_and_reasons_load_as_members_and_write_back_as_the_same_strings():
    from worker.status import RunOutcome, RunReason

    doc = json.loads(EXAMPLE.read_text())
    for outcome, reason, stop in [("completed", None, "map_unchanged"),
                                  ("failed", "slam_failed", "slam_failed"),
                                  ("incomplete", None, "no_frontier")]:  # fmt: skip
        doc.update(outcome=outcome, reason=reason, stop=stop)
        s = RunSummary.load(doc)
        assert s.outcome is RunOutcome(outcome) and s.stop is RunReason(stop)
        assert json.loads(s.to_json_text()) == doc
    with pytest.raises(ValueError):
        RunSummary.load({**doc, "stop": "error"})  # a batch record's state, no stop reason


def test_the_module_imports_neither_numpy_nor_numba():
    code = "import sys, worker.report.summary; print(sorted({'numpy', 'numba'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_json_schema_names_every_field_and_versions_default_to_1():
    schema = summary_json_schema()
    assert schema["properties"]["schema_version"]["default"] == 1
    assert "schema_version" not in schema["required"]
    assert set(schema["required"]) == set(json.loads(EXAMPLE.read_text()))
    timings = schema["$defs"]["Timings"]
    assert "slam_wall_s" not in timings["required"] and "wall_time_s" in timings["required"]


def test_a_fresh_runs_summary_json_is_what_json_dumps_writes_of_it(tmp_path):
    from worker.pipeline import run_one
    from worker.run_params import RunParams

    params = RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 20.0}})
    result = run_one(two_rooms(), params, seed=4)
    write_report(result, tmp_path)
    text = (tmp_path / SUMMARY).read_text()
    doc = json.loads(text)
    # the old writer's bytes: same keys in the same order, the json module's float formatting
    assert _dumps(doc) == text
    # the map-versus-floorplan score (issue 17) is the one section added since, at the end
    assert list(doc) == [*json.loads(EXAMPLE.read_text()), "map_score"]
    assert list(doc["timings"])[-2:] == ["simulation_wall_s", "slam_wall_s"]
    assert doc["params"] == params.to_json() and doc["seed"] == 4
    assert RunSummary.model_validate_json(text) == result.summary


def test_a_summary_without_a_map_score_dumps_without_the_key_one_with_it_keeps_it():
    old = make_summary()
    assert old.map_score is None
    assert "map_score" not in old.to_dict() and '"map_score"' not in old.model_dump_json()
    section = {
        "precision": 0.9, "recall": None, "wall_coverage": 0.5, "distance_m": 0.04,
        "distance_map_m": 0.03, "distance_floorplan_m": 0.05, "free_share": 0.8,
        "tolerance_m": 0.1, "n_map_walls": 10, "n_floorplan_walls": 20,
        "n_floorplan_walls_seen": 12, "icp_iterations": 3, "icp_converged": True,
        "alignment": {"x": 0.0, "y": 0.1, "theta": 0.0},
    }  # fmt: skip
    new = RunSummary.model_validate({**old.to_dict(), "map_score": section})
    assert new.to_dict()["map_score"] == section
    assert RunSummary.model_validate_json(new.to_json_text()) == new


def test_look_through_goals_are_kept_when_counted_and_absent_from_older_runs():
    old = make_summary()
    assert old.goals.look_through is None and "look_through" not in old.to_dict()["goals"]
    new = make_summary(goals={"look_through": 3})
    assert new.to_dict()["goals"] == {**summary_doc()["goals"], "look_through": 3}
    assert RunSummary.model_validate_json(new.to_json_text()) == new


def test_squeeze_goals_are_kept_when_counted_and_absent_from_older_runs():
    old = make_summary()
    assert old.goals.squeeze is None and "squeeze" not in old.to_dict()["goals"]
    new = make_summary(goals={"look_through": 0, "squeeze": 2})
    assert new.to_dict()["goals"] == {**summary_doc()["goals"], "look_through": 0, "squeeze": 2}
    assert RunSummary.model_validate_json(new.to_json_text()) == new
