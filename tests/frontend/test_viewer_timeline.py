"""The viewer's one timeline in headless Chromium, over a real viser server, PostgreSQL and
Redis: a replay's coverage follows the slider, read from the timeline.csv stored with the run
(expected values parsed here from that file, not through the viewer's reader); a run from
before the series was stored says so instead of showing a number; and during a live run the
user drags the timeline back while the run goes on, then returns to live."""

from __future__ import annotations

import csv
import io
import json
import re
import threading
import time

import numpy as np
import pytest
import redis

from backend.core.viewer_tokens import issue
from backend.db.arrays import pack_array
from backend.db.migrate import upgrade
from backend.db.models import Run, RunMap, RunTrajectory
from backend.db.session import session_scope
from backend.store import add_user, create_job, save_world
from frontend.viewer import ViewerApp, run_link
from tests.frontend.conftest import free_port
from tests.frontend.test_browser import _wait
from tests.services import scratch_database
from tests.summaries import summary_doc
from worker.live_wire import channel
from worker.report.timeline import TIMELINE, Timeline
from worker.world.world import World

DURATION = 60.0  # [s] of the finished runs
FINAL_COVERAGE = 0.8


def _room() -> np.ndarray:
    occ = np.zeros((100, 140), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    return occ


def _timeline() -> Timeline:
    """One report a second, the coverage re-estimated every 10 s (as the worker reports it)."""
    tl = Timeline()
    for k in range(1, int(DURATION)):
        cov = FINAL_COVERAGE * (1 - np.exp(-(k // 10) * 10 / 25.0))
        tl.add(float(k), cov, k // 7, "navigating" if k % 2 else "planning")
    return tl


def _done_run(s, owner: int, world: int, report_dir: str | None) -> int:
    job = create_job(s, owner_id=owner, world_id=world, slam="odometry", params={}, seeds=[1])
    run = s.get_one(Run, job.runs[0].id)  # the stored row, to write a worker's results on
    t = np.round(np.arange(int(DURATION * 10)) * 0.1, 1)
    gt = np.column_stack([1.0 + 0.08 * t, 2.0 + 0.02 * t, np.zeros_like(t)])
    for kind, poses in (("gt", gt), ("est", gt + [0.05, 0.0, 0.01])):
        data = pack_array(np.column_stack([t, poses]))
        run.trajectories.append(RunTrajectory(kind=kind, n_poses=len(t), data=data))
    grid = np.full((100, 140), -1, np.int8)
    grid[10:90, 10:130] = 0
    run.map = RunMap(resolution=0.05, origin_x=0.0, origin_y=0.0, width=140, height=100,
                     data=pack_array(grid))  # fmt: skip
    run.summary = summary_doc(outcome="completed", reason=None, stop="no_frontier",
                              coverage=FINAL_COVERAGE)  # fmt: skip
    run.status, run.outcome, run.coverage, run.report_dir = "done", "completed", 0.8, report_dir
    s.flush()
    return run.id


@pytest.fixture(scope="module")
def env(tmp_path_factory, own_redis):
    """A done run with its timeline.csv, an older done run without one, and a running run;
    the viewer over them, on our own Redis."""
    tmp = tmp_path_factory.mktemp("timeline")
    new, old = tmp / "new", tmp / "old"
    new.mkdir()
    old.mkdir()
    _timeline().write(new / TIMELINE)
    (old / "summary.json").write_text("{}")
    with scratch_database("mapqual_timeline") as url:
        upgrade(url)
        with session_scope(url) as s:
            user, _ = add_user(s, "a")
            w = save_world(s, owner_id=user.id, world=World.from_array(_room(), 0.05, name="room"),
                           sha256="room", source_format="image")  # fmt: skip
            runs = {"new": _done_run(s, user.id, w.id, str(new)),
                    "old": _done_run(s, user.id, w.id, str(old))}  # fmt: skip
            job = create_job(s, owner_id=user.id, world_id=w.id, slam="rbpf", params={},
                             seeds=[2])  # fmt: skip
            live = s.get_one(Run, job.runs[0].id)
            live.status = "running"
            s.flush()
            runs["live"], uid = live.id, user.id
        port = free_port()
        app = ViewerApp(url, own_redis.url, "127.0.0.1", port, None)
        yield {"app": app, "url": f"http://127.0.0.1:{port}", "runs": runs, "uid": uid,
               "csv": (new / TIMELINE).read_text(), "redis": own_redis.url}  # fmt: skip
        app.stop()


def _open(browser, env, run: str):
    """A page on the viewer's link for `run`, and that client's view once it shows the run."""
    app, run_id = env["app"], env["runs"][run]
    link = run_link(env["url"], run_id, issue(app.key, run_id, env["uid"], 600))
    page = browser.new_page(viewport={"width": 1300, "height": 850})
    page.set_default_timeout(90_000)
    before = set(app.views)
    page.goto(link)
    view = _wait(lambda: next((app.views[c] for c in set(app.views) - before), None), 60,
                 "the viewer's client")  # fmt: skip
    page.get_by_text(f"Run #{run_id}").first.wait_for()
    for close in page.locator(".mantine-Notification-closeButton").all():
        close.click()  # the software-WebGL notice
    return page, view


def _slide_to(page, share: float) -> None:
    """Click the timeline's slider `share` of the way along its track, as a user does."""
    box = page.locator(".mantine-Slider-root").first.bounding_box()
    page.mouse.click(box["x"] + share * box["width"], box["y"] + box["height"] / 2)


def _shown(page) -> dict:
    """The figures the metrics panel shows in the page."""
    text = " ".join(page.get_by_text("sim time").first.inner_text().split())
    got = {"t": float(re.search(r"sim time ([\d.]+) s", text).group(1))}
    cov = re.search(r"coverage ([\d.]+) %", text)
    got["coverage"] = None if cov is None else float(cov.group(1))
    goals = re.search(r"(\w+), (\d+) goals", text)
    got["status"], got["goals"] = (goals.group(1), int(goals.group(2))) if goals else (None, None)
    return got


def _expected(csv_text: str, t: float) -> tuple[float, str, int]:
    """The stored row of the last report at or before `t`, read with csv alone."""
    rows = [r for r in csv.DictReader(io.StringIO(csv_text)) if float(r["t_s"]) <= t + 1e-6]
    row = rows[-1]
    return round(100 * float(row["coverage"]), 1), row["status"], int(row["goals_reached"])


def test_a_replays_coverage_follows_the_timeline(browser, env, artifacts):
    page, view = _open(browser, env, "new")
    _wait(lambda: view.mode == "replay", 30, "the replay")
    seen = set()
    for share in (0.12, 0.45, 0.8):
        before = view.slider.value
        _slide_to(page, share)
        _wait(lambda b=before: view.slider.value != b, 30, "the slider to move")
        page.wait_for_timeout(800)  # the panel's new text reaches the page
        got = _shown(page)
        assert abs(got["t"] - share * DURATION) < 0.1 * DURATION  # where the user clicked
        cov, status, goals = _expected(env["csv"], got["t"])
        assert (got["coverage"], got["status"], got["goals"]) == (cov, status, goals), got
        seen.add(got["coverage"])
    assert len(seen) == 3 and max(seen) < 100 * FINAL_COVERAGE  # not the final figure
    page.screenshot(path=artifacts / "viewer-replay-timeline.png")
    page.close()


def test_an_old_run_says_its_coverage_over_time_is_not_stored(browser, env):
    page, view = _open(browser, env, "old")
    _wait(lambda: view.mode == "replay", 30, "the replay")
    _slide_to(page, 0.3)
    page.get_by_text("not stored for this run").first.wait_for()
    got = _shown(page)
    assert got["coverage"] is None  # no number for the moment shown
    assert page.get_by_text(f"at the end {100 * FINAL_COVERAGE:.1f} %").count() >= 1
    page.close()


def _publisher(env, stop: threading.Event, sent: list[dict]):
    """The worker's side of a live run: a message every 0.1 s, one simulated second and one
    path point each, the coverage growing, in the wire format of worker.live_wire."""
    r = redis.Redis.from_url(env["redis"])
    k = 0
    while not stop.is_set():
        k += 1
        x, y = 1.0 + 0.1 * k, 2.0 + 0.02 * k
        prog = {"t": float(k), "coverage": round(0.004 * k, 4), "pose_gt": [x, y, 0.0],
                "pose_est": [x + 0.03, y, 0.0], "status": "navigating", "goals_reached": k // 9,
                "rtf": 10.0}  # fmt: skip
        msg = {"progress": prog, "seq": k, "path": {"i0": k - 1, "gt": [[x, y]],
                                                    "est": [[x + 0.03, y]]}}  # fmt: skip
        if r.publish(channel(env["runs"]["live"]), json.dumps(msg)):
            sent.append(prog)
        else:
            k -= 1  # nobody listens yet: the run starts when the viewer does
        time.sleep(0.1)


def test_the_timeline_goes_back_during_a_live_run_and_returns_to_live(browser, env, artifacts):
    page, view = _open(browser, env, "live")
    stop, sent = threading.Event(), []
    pub = threading.Thread(target=_publisher, args=(env, stop, sent), daemon=True)
    pub.start()
    try:
        _wait(lambda: view.mode == "live" and view.slider.max >= 40, 60, "40 s of live run")
        _slide_to(page, 0.3)
        page.get_by_text("looking back").first.wait_for()
        page.wait_for_timeout(500)
        got, edge = _shown(page), view.slider.max
        # 30 % of the page's slider, whose end lags the server's under load
        assert 1.0 < got["t"] < 0.4 * edge
        prog = [p for p in sent if p["t"] <= got["t"] + 1e-6][-1]  # what the worker said then
        assert got["coverage"] == round(100 * prog["coverage"], 1)
        assert got["goals"] == prog["goals_reached"]
        # the run goes on: the live edge moves, the view stays in the past
        _wait(lambda: view.slider.max >= edge + 10, 30, "the live edge to move on")
        page.wait_for_timeout(500)
        assert _shown(page)["t"] == got["t"] and view.slider.value == pytest.approx(
            got["t"], abs=0.1
        )
        box = page.locator(".mantine-NumberInput-input").first  # the slider's own number
        assert float(box.input_value()) == pytest.approx(got["t"], abs=0.05)
        live = view.live
        assert view.describe()["gt_points"] < len(live.gt) / 2
        page.screenshot(path=artifacts / "viewer-live-looking-back.png")
        page.get_by_role("button", name="Back to live").click()
        _wait(lambda: view.following, 20, "the view to return to live")
        page.wait_for_function("!document.body.innerText.includes('looking back')")
        stop.set()  # the run pauses: the page must come to show its last moment
        pub.join(timeout=5)
        last = sent[-1]
        _wait(lambda: _shown(page)["t"] == last["t"], 30, "the live edge shown")
        assert _shown(page)["coverage"] == round(100 * last["coverage"], 1)
        assert view.describe()["gt_points"] == len(live.gt) == len(sent)
    finally:
        stop.set()
        pub.join(timeout=5)
    page.close()
