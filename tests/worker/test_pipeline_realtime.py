"""run_one under real-time emulation: the same seed gives the same run with 1 and 2 threads,
zero latency is today's run byte for byte, and the summary reports what the SLAM kept up with."""

from __future__ import annotations

import pytest

from tests.worker.test_pipeline import two_rooms
from worker.errors import InputError
from worker.pipeline import run_one
from worker.report.summary import RunSummary
from worker.run_params import RunParams


def _run(tmp_path, name: str, **over):
    data = {"algorithm": "rbpf", "explore": {"time_limit": 40.0}, "slam": {"particles": 12}}
    data.update(over)
    log = tmp_path / f"{name}.log"
    return run_one(two_rooms(), RunParams.from_json(data), seed=5, sim_log=log), log


def _without(summary: RunSummary, *keys: str) -> dict:
    doc = summary.to_dict()
    doc.pop("timings")
    for k in keys:
        doc.pop(k, None)
    doc["params"] = {k: v for k, v in doc["params"].items() if k != "realtime"}
    return doc


def test_same_seed_same_realtime_run_with_one_and_two_threads(tmp_path):
    rt = {"speed": 0.02}  # slow enough that scans are dropped
    a, log_a = _run(tmp_path, "a", realtime=rt, slam={"particles": 12, "threads": 1})
    b, log_b = _run(tmp_path, "b", realtime=rt, slam={"particles": 12, "threads": 1})
    c, log_c = _run(tmp_path, "c", realtime=rt, slam={"particles": 12, "threads": 2})
    assert a.summary.realtime is not None and a.summary.realtime.scans_dropped > 0
    assert _without(a.summary) == _without(b.summary)
    doc_c = _without(c.summary)
    doc_c["params"]["slam"]["threads"] = 1
    assert _without(a.summary) == doc_c
    assert log_a.read_bytes() == log_b.read_bytes() == log_c.read_bytes()
    assert a.est.poses.tobytes() == c.est.poses.tobytes()
    # the summary's figures hang together and survive a round trip through JSON
    r = a.summary.realtime
    assert r.updates + r.scans_dropped <= r.scans == len(a.gt.t)
    assert 0 < r.latency_mean_s <= r.latency_max_s
    assert RunSummary.model_validate_json(a.summary.to_json_text()) == a.summary


def test_zero_latency_is_todays_run_byte_for_byte(tmp_path):
    today, log_today = _run(tmp_path, "today")
    zero, log_zero = _run(tmp_path, "zero", realtime={"fixed_latency_s": 0.0})
    assert today.summary.realtime is None and "realtime" not in today.summary.to_dict()
    assert zero.summary.realtime.scans_dropped == 0
    assert _without(zero.summary, "realtime") == _without(today.summary)
    assert log_zero.read_bytes() == log_today.read_bytes()
    assert zero.est.poses.tobytes() == today.est.poses.tobytes()


def test_realtime_params_are_checked():
    with pytest.raises(InputError, match="realtime.speed"):
        RunParams.from_json({"realtime": {"speed": -1}})
    with pytest.raises(InputError, match="no cost model"):
        RunParams.from_json({"algorithm": "graph", "realtime": {"speed": 1.0}})
    with pytest.raises(InputError):
        RunParams.from_json({"algorithm": "oracle", "realtime": {"fixed_latency_s": 0.1}})
    with pytest.raises(InputError):
        RunParams.from_json({"algorithm": "mrpt_rbpf"})
    p = RunParams.from_json({"algorithm": "graph", "realtime": {"fixed_latency_s": 0.5}})
    assert RunParams.from_json(p.to_json()) == p
    assert RunParams.from_json({}).realtime is None
