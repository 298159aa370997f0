"""The worker's live feed on real Redis: light while nobody listens; a new listener gets the
whole path and map, then only new points and changed map rectangles, and rebuilds both
exactly; the viewer's LiveRun folds the messages into the same state. (The wire format's
pieces alone: tests/worker/test_live_wire.py.)"""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import redis

from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.services.progress import ProgressReporter
from backend.store import add_user, create_job, mark_run_started, save_world
from frontend.live import LiveRun
from worker.live_wire import channel, map_codes
from worker.pipeline import RunProgress
from worker.slam.grid import OccupancyGrid
from worker.world.world import World


def _progress(t, pose, grid, ranges=None, angles=None) -> RunProgress:
    pose = np.asarray(pose, dtype=float)
    return RunProgress(
        t, 0.5, pose, pose + 0.01, "driving", 1, t / 10, 10.0,
        goal_xy=np.array([3.0, 4.0]), plan=np.array([[0.0, 0.0], [3.0, 4.0]]), ranges=ranges,
        occupancy=None if grid is None else (lambda: grid), beam_angles=angles, range_max=30.0,
    )  # fmt: skip


@pytest.fixture()
def feed(tmp_path, own_redis):
    url = f"sqlite:///{tmp_path / 'feed.db'}"
    upgrade(url)
    occ = np.zeros((40, 40), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    with session_scope(url) as s:
        uid = add_user(s, "u")[0].id
        w = save_world(s, owner_id=uid, world=World.from_array(occ, 0.1), sha256="h",
                       source_format="image")  # fmt: skip
        run_id = create_job(s, owner_id=uid, world_id=w.id, slam="rbpf", params={}, seeds=[1])
        run_id = run_id.runs[0].id
        mark_run_started(s, run_id)
    client = redis.Redis.from_url(own_redis.url)
    yield url, run_id, client
    client.close()


def _grid(step: int) -> OccupancyGrid:
    prob = np.full((60, 80), np.nan, np.float32)
    prob[10 : 20 + 3 * step, 10:30] = 0.05  # the free area grows with each step
    prob[10 + step, 40 + step] = 0.9  # and one obstacle moves
    return OccupancyGrid(prob, 0.05, (-1.0, -1.5))


def test_a_listener_gets_the_whole_state_then_only_changes(feed):
    url, run_id, client = feed
    rep = ProgressReporter(
        url, run_id, client, publish_every_s=0.0, map_every_s=0.0, idle_publish_every_s=0.0
    )
    poses = [np.array([0.1 * i, 0.05 * i, 0.0]) for i in range(12)]
    rep(_progress(0.0, poses[0], _grid(0)))  # nobody listens: a light message
    assert rep._listeners == 0
    sub = client.pubsub(ignore_subscribe_messages=True)
    sub.subscribe(channel(run_id))
    sub.get_message(timeout=1.0)
    live = LiveRun(run_id)
    for i in range(1, 12):
        rep(_progress(float(i), poses[i], _grid(i)))
        msg = sub.get_message(timeout=2.0)
        assert msg is not None
        doc = json.loads(msg["data"])
        if i == 1:  # noticed the listener when publishing: this message is still light
            assert "path" not in doc and "map" not in doc
        if i == 2:  # the first full message: every point so far, the whole map
            assert doc["path"]["i0"] == 0 and len(doc["path"]["gt"]) == 3 and doc["map"]["full"]
        if i > 2:  # one new point, and only the changed rectangle of the map
            assert doc["path"]["i0"] == i and len(doc["path"]["gt"]) == 1
            assert not doc["map"]["full"] and doc["map"]["box"][2] < 60
        live.apply(doc)
    sub.close()
    np.testing.assert_allclose(live.gt, np.array(poses)[:, :2], atol=1e-3)
    np.testing.assert_allclose(live.est, np.array(poses)[:, :2] + 0.01, atol=1e-3)
    np.testing.assert_array_equal(live.map.codes, map_codes(_grid(11)))
    assert live.map.origin == (-1.0, -1.5) and live.map.resolution == 0.05
    assert live.progress["t"] == 11.0 and live.goal.tolist() == [3.0, 4.0]


def test_progress_is_stored_and_a_cancelled_run_stops(feed):
    from backend.db.models import Run
    from worker.pipeline import RunCancelled

    url, run_id, client = feed
    rep = ProgressReporter(url, run_id, client, store_every_s=0.0)
    rep(_progress(3.0, [1.0, 2.0, 0.5], None))
    with session_scope(url) as s:
        run = s.get_one(Run, run_id)
        assert run.progress["t"] == 3.0 and run.progress["pose_gt"] == [1.0, 2.0, 0.5]
        run.status = "cancelled"
    time.sleep(0.01)
    with pytest.raises(RunCancelled):
        rep(_progress(4.0, [1.0, 2.0, 0.5], None))
