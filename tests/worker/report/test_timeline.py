"""timeline.csv: a run's progress reports against simulated time, stored with its report for the
viewer's replay. Checked against the reports the run's own progress callback received."""

from __future__ import annotations

import csv
import io

import pytest

from tests.worker.test_pipeline import two_rooms
from worker.pipeline import run_one
from worker.report.folder import write_report
from worker.report.timeline import TIMELINE, Timeline
from worker.run_params import RunParams

PARAMS = {"algorithm": "oracle", "explore": {"time_limit": 40.0}}


def test_a_run_stores_every_progress_report_it_gave(tmp_path):
    got = []
    result = run_one(
        two_rooms(), RunParams.from_json(PARAMS), 2,
        lambda p: got.append((p.t, p.coverage, p.goals_reached, p.status)),
    )  # fmt: skip
    write_report(result, tmp_path)
    rows = list(csv.DictReader(io.StringIO((tmp_path / TIMELINE).read_text())))
    assert len(rows) == len(got) >= 5  # one report a simulated second
    for row, (t, cov, goals, status) in zip(rows, got, strict=True):
        assert float(row["t_s"]) == pytest.approx(t, abs=5e-4)
        assert float(row["coverage"]) == pytest.approx(cov, abs=5e-5)
        assert (int(row["goals_reached"]), row["status"]) == (goals, status)
    ts = [float(r["t_s"]) for r in rows]
    assert all(b - a == pytest.approx(1.0, abs=1e-3) for a, b in zip(ts, ts[1:], strict=False))
    # the coverage is re-estimated every 10 s: it changes at most once in each 10 s
    covs = [float(r["coverage"]) for r in rows]
    changes = [ts[i] for i in range(1, len(covs)) if covs[i] != covs[i - 1]]
    assert all(round(t) % 10 == 0 for t in changes)
    assert (tmp_path / TIMELINE).stat().st_size < 40 * len(rows)  # small


def test_a_run_without_progress_reports_writes_no_timeline(tmp_path):
    write_report(run_one(two_rooms(), RunParams.from_json(PARAMS), 2), tmp_path)
    assert (tmp_path / "summary.json").is_file() and not (tmp_path / TIMELINE).exists()


def test_the_figures_at_a_moment_are_the_last_report_by_then():
    tl = Timeline()
    for t, cov in ((1.0, 0.0), (2.0, 0.0), (3.0, 0.25)):
        tl.add(t, cov, int(t), "navigating")
    back = Timeline.from_csv(tl.to_csv())
    assert back.at(0.99) is None  # before the first report
    assert back.at(2.0)["coverage"] == 0.0 and back.at(2.0)["goals_reached"] == 2
    assert back.at(2.999)["t_report"] == 2.0
    assert back.at(3.0)["coverage"] == 0.25 and back.at(1e6)["coverage"] == 0.25
    with pytest.raises(ValueError, match="header"):
        Timeline.from_csv("t,coverage\n1,0.5\n")
