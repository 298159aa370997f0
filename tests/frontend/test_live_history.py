"""The past a live viewer keeps to look back into: exact while short, thinned by half when it
reaches its bound, so a long watch keeps a bounded number of moments, evenly spread."""

from __future__ import annotations

from frontend.live import LiveRun


def _message(k: int) -> dict:
    x = 0.1 * k
    return {"progress": {"t": float(k), "coverage": k / 1000, "pose_gt": [x, 0.0, 0.0],
                         "pose_est": [x, 0.01, 0.0]},
            "path": {"i0": k - 1, "gt": [[x, 0.0]], "est": [[x, 0.01]]}}  # fmt: skip


def test_looking_back_gives_the_moment_received_then():
    live = LiveRun(1)
    for k in range(1, 51):
        live.apply(_message(k))
    gt, est, p = live.at(20.5)
    assert p["t"] == 20.0 and p["coverage"] == 0.02  # the last message at or before 20.5 s
    assert len(gt) == len(est) == 20  # one path point a message, 20 by then
    assert live.at(0.5)[2] is None  # before the first message


def test_a_long_watch_keeps_a_bounded_past_evenly_thinned():
    live = LiveRun(1, max_history=64)
    for k in range(1, 1001):
        live.apply(_message(k))
    assert 32 <= len(live.hist_t) <= 64
    gaps = [b - a for a, b in zip(live.hist_t, live.hist_t[1:], strict=False)]
    assert max(gaps) <= 2 * min(gaps) and 1000.0 - live.hist_t[-1] < max(gaps)
    for t in (10.0, 333.3, 777.0, 999.9):
        _, _, p = live.at(t)
        assert 0 <= t - p["t"] <= max(gaps)  # the nearest kept moment before
        assert len(live.at(t)[0]) == int(t)  # the path itself is kept whole
