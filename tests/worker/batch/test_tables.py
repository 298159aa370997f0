"""Batch tables from hand-made records, against figures worked out by hand; figures and page."""

from __future__ import annotations

import csv

import pytest

from tests.summaries import make_summary
from worker.batch.experiment import RunSpec
from worker.batch.results import write_results
from worker.batch.state import BatchDir, record_of


def _stats(mean, std, lo, hi, n):
    return {"mean": mean, "std": std, "min": lo, "max": hi, "n": n, "mean_squared": None}


def _rec(world, seed, outcome="completed", reason=None, t=(0.5, 0.2, 0.0, 2.0, 100),
         r=(0.01, 0.005, 0.0, 0.05, 100), noise=0.0, error=None):  # fmt: skip
    base = world.removesuffix("_furnitures")
    variant = "furniture" if world != base else "no_furniture"
    spec = RunSpec(f"{world}{seed}{noise}", f"/w/{world}.yaml", world, base, variant, "rbpf",
                   noise, seed, {})  # fmt: skip
    if error:
        return record_of(spec, summary=None, error=error)
    rel = {"translation": _stats(*t), "rotation": _stats(*r), "skipped": 0}
    a = {"translation": _stats(0.01, 0, 0, 0.1, 50), "rotation": _stats(0.001, 0, 0, 0.01, 50)}
    summary = make_summary(
        outcome=outcome, reason=reason, stop=reason or "no_frontier", coverage=0.9,
        path_length_m=10.0, relations={"B": rel, "A": {**a, "skipped": 0}}, ate=None,
        timings={"sim_time_s": 100.0, "wall_time_s": 10.0, "real_time_factor": 10.0},
    )  # fmt: skip
    return record_of(spec, summary=summary)


@pytest.fixture
def records():
    return [
        _rec("office", 1, t=(0.4, 0.2, 0.01, 2.0, 100), r=(0.010, 0.004, 0.0, 0.04, 100)),
        _rec("office", 2, t=(0.6, 0.4, 0.03, 4.0, 300), r=(0.020, 0.006, 0.0, 0.08, 300)),
        _rec("office", 3, "failed", "collision", t=(5.0, 1.0, 0.0, 9.0, 10)),
        _rec("office", 4, error="ValueError: boom"),
        _rec("office_furnitures", 1, t=(1.5, 0.5, 0.1, 3.0, 200)),
        _rec("office_furnitures", 2, "failed", "stuck"),
        _rec("office", 1, noise=0.3, t=(0.9, 0.3, 0.0, 3.0, 80)),
    ]


def _read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_tables_match_hand_computed_figures(tmp_path, records):
    files = write_results(records, BatchDir(tmp_path), expected=8)
    runs = _read(files["runs"])
    assert len(runs) == 7
    assert runs[3]["outcome"] == "failed" and runs[3]["reason"] == "error"
    assert runs[3]["error"] == "ValueError: boom" and runs[3]["b_mean_t"] == ""
    assert float(runs[1]["b_max_t"]) == 4.0 and runs[1]["good"] == "true"
    assert runs[4]["good"] == "false"  # completed, but 1.5 m > 1 m: visually bad
    success = {(r["world"], r["noise"]): r for r in _read(files["success"])}
    office = success[("office", "0.0")]
    assert (office["runs"], office["completed"], office["good"], office["failed"]) == (
        "4", "2", "2", "2"
    )  # fmt: skip
    assert (office["collision"], office["error"], office["stuck"]) == ("1", "1", "0")
    assert success[("office_furnitures", "0.0")]["stuck"] == "1"
    trans = {r["ENVIRONMENT"]: r for r in _read(files["translation"])}
    # the noise varies in this batch, so it names the environment; averages of completed runs
    assert list(trans) == ["office noise 0", "office_furnitures noise 0", "office noise 0.3"]
    row = trans["office noise 0"]
    expect = {"MEAN": 0.5, "STD": 0.3, "MIN": 0.02, "MAX": 3.0, "NUMMEASURES": 200.0}
    assert {k: pytest.approx(float(row[k])) for k in expect} == expect
    rot = {r["ENVIRONMENT"]: r for r in _read(files["rotation"])}["office noise 0"]
    assert float(rot["MEAN"]) == pytest.approx(0.015) and float(rot["MAX"]) == pytest.approx(0.06)
    assert list(rot) == ["ENVIRONMENT", "MEAN", "STD", "MIN", "MAX", "NUMMEASURES", "CI95"]
    assert rot["CI95"] == ""  # summaries from before the half-width: none to average


def test_ci95_is_the_runs_average_half_width_beside_each_mean(tmp_path):
    recs = [_rec("office", s) for s in (1, 2, 3)]
    for rec, ci in zip(recs, (0.02, 0.04, None), strict=True):
        b = rec["summary"].relations["B"]
        t = b.translation.model_copy(update={"ci95": ci})
        r = b.rotation.model_copy(update={"ci95": None if ci is None else ci / 10})
        rel = b.model_copy(update={"translation": t, "rotation": r})
        rec["summary"] = rec["summary"].model_copy(update={"relations": {"B": rel}})
    files = write_results(recs, BatchDir(tmp_path), expected=3)
    # the third run has no half-width: the average is over the two that have one
    assert float(_read(files["translation"])[0]["CI95"]) == pytest.approx(0.03)
    assert float(_read(files["rotation"])[0]["CI95"]) == pytest.approx(0.003)
    runs = _read(files["runs"])
    assert [r["b_ci95_t"] for r in runs] == ["0.02", "0.04", ""]
    assert runs[0]["b_ci95_r"] == "0.002"
    page = files["report"].read_text()
    assert "0.0200, 0.0020" in page  # the runs table: the half-widths beside the means


def test_every_figure_is_drawn_and_embedded_in_the_page(tmp_path, records):
    files = write_results(records, BatchDir(tmp_path), expected=8)
    page = files["report"].read_text()
    for name in ("errors_by_world.png", "furniture.png", "noise.png", "a_vs_b.png"):
        assert files[name].read_bytes()[:4] == b"\x89PNG"
        assert f'alt="{name}" src="data:image/png;base64,' in page
    assert "7 of 8 runs finished: 4 completed" in page
    assert "ValueError: boom" in page


def test_figures_without_data_are_left_out_and_said_so(tmp_path):
    recs = [_rec("office", 1, "failed", "stuck"), _rec("office", 2, error="RuntimeError: x")]
    files = write_results(recs, BatchDir(tmp_path), expected=2)
    assert files["errors_by_world.png"] is None and files["furniture.png"] is None
    assert files["noise.png"] is None
    assert _read(files["translation"]) == []
    page = files["report"].read_text()
    assert "not drawn (no completed run with B relations yet)" in page


def _map_score(distance, precision, free_share):
    return {
        "precision": precision, "recall": 0.9, "wall_coverage": 0.5, "distance_m": distance,
        "distance_map_m": distance, "distance_floorplan_m": distance, "free_share": free_share,
        "tolerance_m": 0.1, "n_map_walls": 10, "n_floorplan_walls": 20,
        "n_floorplan_walls_seen": 12, "icp_iterations": 3, "icp_converged": True,
        "alignment": {"x": 0.0, "y": 0.0, "theta": 0.0},
    }  # fmt: skip


def _with_map(rec, score):
    summary = rec["summary"]
    return {**rec, "summary": summary.model_validate(summary.to_dict() | {"map_score": score})}


def test_map_scores_go_to_runs_csv_and_their_means_to_maps_csv(tmp_path, records):
    recs = list(records)
    recs[0] = _with_map(recs[0], _map_score(0.04, 0.9, 0.8))
    recs[1] = _with_map(recs[1], _map_score(0.10, None, 0.6))  # a null precision
    recs[2] = _with_map(recs[2], _map_score(1.00, 0.1, 0.1))  # failed: not in maps.csv
    files = write_results(recs, BatchDir(tmp_path), expected=8)
    runs = _read(files["runs"])
    assert (runs[0]["map_distance_m"], runs[0]["map_precision"]) == ("0.04", "0.9")
    assert runs[1]["map_precision"] == "" and runs[4]["map_distance_m"] == ""
    maps = {r["ENVIRONMENT"]: r for r in _read(files["maps"])}
    # office, noise 0: completed runs 1 and 2 have scores; distance (0.04 + 0.10) / 2,
    # precision 0.9 alone (the other is null), free share (0.8 + 0.6) / 2
    office = maps["office noise 0"]
    assert float(office["MAP_DISTANCE_M"]) == pytest.approx(0.07)
    assert float(office["MAP_PRECISION"]) == pytest.approx(0.9)
    assert float(office["MAP_FREE_SHARE"]) == pytest.approx(0.7)
    assert office["RUNS"] == "2"
    assert set(maps) == {"office noise 0"}  # no other environment has a scored completed run
