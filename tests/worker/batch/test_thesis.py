"""The thesis side by side: the transcribed tables spot-checked by hand, the comparison and
the findings on hand-made records, and the report's section."""

from __future__ import annotations

import csv

import pytest

from tests.worker.batch.test_tables import _rec
from worker.batch.results import write_results
from worker.batch.state import BatchDir
from worker.batch.thesis import (
    a_finding,
    auc,
    findings,
    furniture_finding,
    noise_findings,
    side_by_side,
    tables,
    thesis_name,
    thesis_row,
)


def test_transcription_spot_checked_against_the_thesis_text():
    # read by hand in shared/reference/thesis-map-quality-evaluation.md
    t = tables()["tables"]
    assert t["6.3"]["success"]["lab_f"] == 6 and t["6.3"]["success"]["office_h_furnitures"] == 7
    assert t["6.3"]["success"]["freiburg52_furnitures"] == 10 and len(t["6.3"]["success"]) == 14
    assert t["6.4"]["rows"]["office_a"] == [0.6006, 0.6256, 0.0033, 9.0297, 6328.1071]
    assert t["6.4"]["rows"]["lab_f"][3] == 66.8112 and t["6.4"]["rows"]["lab_f"][4] == 23210.3333
    assert t["6.5"]["rows"]["lab_c"] == [0.0238, 0.0916, 0.0, 1.1689, 216.2222]
    assert t["6.5"]["rows"]["scuola_sconosciuta_3"][0] == 0.0111
    assert len(t["6.4"]["rows"]) == len(t["6.5"]["rows"]) == 37
    assert t["6.4"]["title"].startswith("Table 6.4") and t["6.5"]["title"].startswith("Table 6.5")


def test_our_world_names_map_to_the_thesiss():
    assert thesis_name("Freiburg52_scan") == "freiburg52"
    assert thesis_name("lab_c_scan_furnitures") == "lab_c_furnitures"
    assert thesis_name("Freiburg79_scan") == "freiburg"  # the assumed alias
    assert thesis_name("office_a") == "office_a"
    row = thesis_row("lab_c_scan_furnitures")
    assert row.success == 10 and row.translation is None  # Tables 6.4/6.5: no furnished plan
    assert thesis_row("office_a").success is None  # office_a is not in Table 6.3's sample
    assert thesis_row("office_a").rotation["max"] == 0.1789
    assert thesis_row("office_a_furnitures") is None and thesis_row("my_flat") is None


def test_side_by_side_and_the_2x_flag():
    recs = [
        _rec("office_a", 1, t=(0.3, 0.2, 0.0, 2.0, 500)),
        _rec("office_a", 2, t=(0.9, 0.4, 0.0, 4.0, 700)),
        _rec("office_a", 3, "failed", "stuck"),
        _rec("lab_b_scan", 1, t=(0.5, 0.2, 0.0, 2.0, 500)),
        _rec("my_flat", 1),
        _rec("office_a", 1, noise=0.1),
    ]
    rows = {r["world"]: r for r in side_by_side(recs)}
    assert list(rows) == ["office_a", "lab_b_scan"]  # my_flat: not in the thesis
    a = rows["office_a"]
    assert (a["runs"], a["good"], a["thesis_success"]) == (3, 2, None)
    assert a["mean_t"] == pytest.approx(0.6) and a["thesis_mean_t"] == 0.6006
    assert a["max_t"] == pytest.approx(3.0) and a["n_t"] == pytest.approx(600)
    assert a["thesis_n_t"] == 6328.1071 and a["thesis_max_r"] == 0.1789
    assert a["ratio_t"] == pytest.approx(0.6 / 0.6006) and not a["far"]
    b = rows["lab_b_scan"]
    assert b["ratio_t"] == pytest.approx(0.5 / 0.1735) and b["far"]  # 2.9x


def test_auc_by_hand():
    # bad [0.02, 0.03] against good [0.01, 0.04]: 2 of the 4 pairs have bad > good
    assert auc([0.02, 0.03], [0.01, 0.04]) == 0.5
    assert auc([0.5, 0.6], [0.1, 0.2]) == 1.0 and auc([0.1], [0.1]) == 0.5


def test_findings_on_hand_made_runs():
    def with_a(rec, a_mean):
        s = rec["summary"]
        a = s.relations["A"]
        t = a.translation.model_copy(update={"mean": a_mean})
        rels = {**s.relations, "A": a.model_copy(update={"translation": t})}
        return {**rec, "summary": s.model_copy(update={"relations": rels})}

    recs = [
        with_a(_rec("office", 1, t=(0.4, 0.1, 0, 1, 9)), 0.01),
        with_a(_rec("office", 2, t=(0.5, 0.1, 0, 1, 9)), 0.04),
        with_a(_rec("office_furnitures", 1, t=(1.5, 0.1, 0, 1, 9)), 0.02),
        with_a(_rec("office_furnitures", 2, t=(2.5, 0.1, 0, 1, 9)), 0.03),
        _rec("office", 1, noise=0.3, t=(0.9, 0.3, 0.0, 3.0, 80)),
        _rec("office", 2, "failed", "collision", noise=0.3),
    ]
    f = furniture_finding(recs)
    assert f["holds"] and "office 0.450 -> 2.000 m" in f["evidence"]
    success, error = noise_findings(recs)
    assert success["holds"] and "good 100% at 0 m, 50% at 0.3 m" in success["evidence"]
    # the error over every run with B relations: the collision's 0.5 m counts too
    assert error["holds"] and "0.450 m at 0 m, 0.700 m at 0.3 m" in error["evidence"]
    # bad (B over 1 m) A means 0.02, 0.03 against good 0.01, 0.04 and 0.01 (the noisy run,
    # 0.9 m): 4 of the 6 pairs have bad > good
    a = a_finding(recs)
    assert a["holds"] and "AUC of mean A error, 2 bad against 3 good runs: 0.67" in a["evidence"]
    nothing = findings([_rec("office", 1)])
    assert [x["holds"] for x in nothing] == [None, None, None, None]


def test_the_report_shows_the_thesis_beside_ours(tmp_path):
    recs = [_rec("office_a", 1, t=(0.3, 0.2, 0.0, 2.0, 500)), _rec("lab_b_scan", 1)]
    files = write_results(recs, BatchDir(tmp_path), expected=2)
    page = files["report"].read_text()
    assert "The thesis side by side (Tables 6.3, 6.4, 6.5)" in page
    assert "<td>0.3000 / 0.6006</td>" in page and "<td>500 / 6328</td>" in page
    assert "furniture raises the error" in page and "not checked" in page
    with open(files["thesis"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["thesis_name"] for r in rows] == ["office_a", "lab_b"]
    assert rows[1]["far"] == "true"  # 0.5 m against 0.1735 m
