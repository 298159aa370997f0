"""What a real-time SLAM kept up with (issue 51), where a user looks: every progress message
of an emulated run carries its updates, dropped scans and latencies so far; the viewer's panel
and the dashboard's run section show them."""

from __future__ import annotations

import re

import pytest
from fastapi.testclient import TestClient

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user, create_job, mark_run_started, save_world, store_run_result
from frontend.panel import metrics_markdown, realtime_line
from mapqual.app import create_app
from tests.frontend.test_pages import rooms
from tests.services import ensure_redis
from worker.live_wire import progress_payload
from worker.pipeline import run_one
from worker.run_params import RunParams
from worker.world.world import World

LATENCY_S = 0.25  # every update; the laser gives a scan every 0.1 s


@pytest.fixture(scope="module")
def emulated():
    """An odometry run of 30 s whose every update takes 0.25 s, with its progress messages."""
    world = World.from_array(rooms(2, 1), 0.05, name="rt_rooms")
    params = RunParams.from_json(
        {"algorithm": "odometry", "explore": {"time_limit": 30.0},
         "realtime": {"fixed_latency_s": LATENCY_S}}
    )  # fmt: skip
    seen = []
    result = run_one(world, params, 3, on_progress=seen.append)
    return world, result, [progress_payload(p) for p in seen]


def test_progress_messages_count_what_the_slam_kept_up_with(emulated):
    _, result, msgs = emulated
    rts = [m["realtime"] for m in msgs]
    assert len(rts) >= 10  # one message a simulated second (the two rooms take ~15 s)
    for key in ("scans", "updates", "scans_dropped"):  # counters only grow
        values = [r[key] for r in rts]
        assert values == sorted(values) and values[-1] > 0, key
    final = result.summary.realtime
    assert rts[-1]["scans"] <= final.scans and rts[-1]["updates"] <= final.updates
    for r in rts:
        # by hand: an update started at a scan publishes 0.25 s later, so the two scans that
        # arrive 0.1 and 0.2 s after it are dropped and the third starts the next update
        assert 2 * (r["updates"] - 1) <= r["scans_dropped"] <= 2 * r["updates"]
        # the rest were processed without an update (the robot had not moved enough)
        assert r["scans"] >= r["updates"] + r["scans_dropped"]
        assert r["latency_mean_s"] == r["latency_max_s"] == LATENCY_S
        assert r["fixed_latency_s"] == LATENCY_S


def test_a_run_without_emulation_sends_no_realtime_figures():
    world = World.from_array(rooms(2, 1), 0.05, name="rt_rooms")
    seen = []
    run_one(world, RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 3}}),
            3, on_progress=seen.append)  # fmt: skip
    assert seen and all("realtime" not in progress_payload(p) for p in seen)


def test_the_viewer_panel_line_is_the_counters():
    rt = {"speed": 0.35, "fixed_latency_s": None, "scans": 1818, "updates": 336,
          "scans_dropped": 1344, "latency_mean_s": 0.4953, "latency_max_s": 0.5}  # fmt: skip
    line = realtime_line(rt)
    assert line == (
        "real-time SLAM (computer x0.35): **336** updates, **1,344** of 1,818 scans dropped "
        "(74 %), latency 0.495 s mean, 0.500 s max"
    )
    assert line in metrics_markdown(None, {"t": 12.0, "realtime": rt}, None)
    assert "real-time SLAM" not in metrics_markdown(None, {"t": 12.0}, None)


def test_the_panel_of_a_finished_run_reads_its_summary(emulated):
    _, result, _ = emulated
    text = metrics_markdown(None, {}, result.summary)
    r = result.summary.realtime
    assert f"latency fixed at {LATENCY_S:g} s" in text
    assert f"**{r.updates:,}** updates, **{r.scans_dropped:,}** of {r.scans:,} scans" in text
    assert text.count("real-time SLAM") == 1 and "max (whole run)" in text


def test_the_job_page_shows_the_runs_realtime_figures(emulated, tmp_path):
    world, result, _ = emulated
    url = f"sqlite:///{tmp_path / 'rt.db'}"
    upgrade(url)
    ex = result.exploration
    with session_scope(url) as s:
        a, key = add_user(s, "a")
        w = save_world(s, owner_id=a.id, world=world, sha256="rt", source_format="image")
        job = create_job(s, owner_id=a.id, world_id=w.id, slam="odometry", params={}, seeds=[3])
        run_id, job_id = job.runs[0].id, job.id
        mark_run_started(s, run_id)
        store_run_result(
            s, run_id, summary=result.summary, t=ex.t, pose_gt=ex.pose_gt, pose_est=ex.pose_est,
            map_ros=ex.final_map.to_ros(), map_resolution=ex.final_map.resolution,
            map_origin=ex.final_map.origin, report_dir=None,
        )  # fmt: skip
    settings = Settings(DATABASE_URL=url, REDIS_URL=ensure_redis().rsplit("/", 1)[0] + "/15")
    client = TestClient(create_app(settings), base_url="https://testserver")
    r = client.post("/login", data={"key": key, "next": "/"}, follow_redirects=False)
    assert r.status_code == 303
    page = client.get(f"/jobs/{job_id}").text
    r = result.summary.realtime
    table = re.search(r'<table class="realtime">.*?</table>', page, re.S).group(0)
    cells = re.findall(r"<td>([^<]*)</td>", table)
    share = f"{100 * r.scans_dropped / r.scans:.0f}"
    assert cells == [
        f"{r.updates:,}",
        f"{r.scans_dropped:,} of {r.scans:,} ({share} %)",
        "0.250 s",
        "0.250 s",
    ]
    assert "every update 0.25 s" in table
