"""A run's timeline reaches the viewer through the storage layer: a run executed as a worker
executes it, with its report in S3 (moto's server over HTTP) and no copy left on the worker's
disk, replays in the viewer with the figures its own progress callback received."""

from __future__ import annotations

import pytest

from backend.services.execute import execute_run
from frontend.live import load_finished
from frontend.panel import replay_figures
from tests.backend.test_execute import _rooms, _run, pg_url  # noqa: F401
from tests.backend.test_execute_s3 import _settings, s3env  # noqa: F401
from tests.s3server import make_bucket


def test_the_viewer_replays_a_runs_timeline_from_s3(pg_url, tmp_path, s3env):  # noqa: F811
    bucket = make_bucket(s3env)
    run_id = _run(pg_url, "oracle", 20.0, _rooms(2, 1))
    got: list[tuple] = []
    out = execute_run(
        run_id, _settings(pg_url, tmp_path, f"s3://{bucket}/p"),
        on_progress=lambda p: got.append((p.t, p.coverage, p.goals_reached, p.status)),
    )  # fmt: skip
    assert out.kind == "done" and out.report_dir.startswith(f"s3://{bucket}/")
    assert list((tmp_path / "scratch").iterdir()) == []  # nothing on this disk to read
    fin = load_finished(pg_url, run_id)
    assert fin is not None and fin.timeline is not None, fin and fin.timeline_note
    assert len(fin.timeline) == len(got) >= 10
    for i, (t, cov, goals, status) in enumerate(got):
        assert fin.timeline.t[i] == pytest.approx(t, abs=5e-4)
        shown = replay_figures(fin, fin.timeline.t[i])  # what the panel shows at that moment
        assert shown["coverage"] == pytest.approx(cov, abs=5e-5)
        assert (shown["goals_reached"], shown["status"]) == (goals, status)
