"""The batch report's validity section: Spearman's rho counted by hand, per noise level."""

from __future__ import annotations

import pytest

from tests.summaries import make_summary, relation, stats
from tests.worker.batch.test_html import _Page, _spec
from worker.batch.html import write_html
from worker.batch.state import record_of
from worker.batch.validity import points, rho_rows, validity


def _score(distance: float, precision: float) -> dict:
    return {"precision": precision, "recall": precision, "wall_coverage": precision,
            "distance_m": distance, "distance_map_m": distance, "distance_floorplan_m": distance,
            "free_share": 0.9, "tolerance_m": 0.1, "n_map_walls": 100, "n_floorplan_walls": 100,
            "n_floorplan_walls_seen": 90, "icp_iterations": 3, "icp_converged": True,
            "alignment": {"x": 0.0, "y": 0.0, "theta": 0.0}}  # fmt: skip


def _rec(seed: int, noise: float, b_t: float, distance: float, precision: float) -> dict:
    b = relation(stats(b_t, 0.1, 500), stats(0.01 * b_t, 0.001, 500))
    s = make_summary(outcome="completed", reason=None, relations={"B": b},
                     map_score=_score(distance, precision))  # fmt: skip
    return record_of(_spec("office", seed, noise), summary=s)


def _batch() -> list[dict]:
    # noise 0: B 0.1 < 0.2 < 0.3 < 0.4, distances ranked 1, 2, 4, 3: sum d^2 = 2, so
    # rho = 1 - 6 * 2 / (4 * 15) = 0.8; precision falls with B throughout: rho = -1.
    # noise 0.3: B 0.15, 0.25, 0.35 with distances ranked 3, 2, 1: rho = -1.
    # Pooled over 7 runs, B ranks (0.1 .. 0.4): 1 3 5 7 | 2 4 6; distances 0.01 0.02 0.04 0.03
    # | 0.5 0.4 0.3 rank 1 2 4 3 | 7 6 5: d = 0 1 1 4 | 5 2 1, sum d^2 = 48, rho = 1 - 288/336.
    return [
        _rec(1, 0.0, 0.1, 0.01, 0.9), _rec(2, 0.0, 0.2, 0.02, 0.8),
        _rec(3, 0.0, 0.3, 0.04, 0.7), _rec(4, 0.0, 0.4, 0.03, 0.6),
        _rec(5, 0.3, 0.15, 0.5, 0.5), _rec(6, 0.3, 0.25, 0.4, 0.4), _rec(7, 0.3, 0.35, 0.3, 0.3),
    ]  # fmt: skip


def test_rho_pooled_and_per_noise_level_match_the_hand_count():
    rows = {r["group"]: r for r in rho_rows(points(_batch()))}
    assert rows["all runs"]["runs"] == 7
    assert rows["all runs"]["t wall distance"] == pytest.approx(1 - 288 / 336)
    assert rows["noise 0 m"]["t wall distance"] == pytest.approx(0.8)
    assert rows["noise 0 m"]["t precision"] == pytest.approx(-1.0)
    assert rows["noise 0.3 m"]["t wall distance"] == pytest.approx(-1.0)
    # rotation is 1 % of translation here, so it ranks the runs alike
    assert rows["noise 0 m"]["r wall distance"] == pytest.approx(0.8)


def test_too_few_scored_runs_leave_the_section_out(tmp_path):
    recs = _batch()[:2] + [record_of(_spec("office", 9), summary=None, error="ValueError: x")]
    assert validity(recs, tmp_path) is None
    text = write_html(recs, {}, tmp_path, {}, expected=3).read_text()
    assert "agree with the relations" not in text


def test_the_report_shows_the_table_and_embeds_the_scatter_plot(tmp_path):
    text = write_html(_batch(), {}, tmp_path, {}, expected=7).read_text()
    page = _Page()
    page.feed(text)
    assert page.balanced
    table = next(t for t in page.tables if t[0][0] == "group")
    assert table[1][:3] == ["all runs", "7", "0.1429"]  # 1 - 288 / 336 = 0.142857
    assert [r[0] for r in table[1:]] == ["all runs", "noise 0 m", "noise 0.3 m"]
    assert (tmp_path / "validity.png").read_bytes()[:4] == b"\x89PNG"
    assert 'alt="validity.png" src="data:image/png;base64,' in text
