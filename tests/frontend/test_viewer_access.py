"""The viewer's authority, on a real viser server over a real PostgreSQL database: a client
without a valid link (none, the old tokenless one, altered, expired, another run's, a revoked
user's) gets a note and nothing of any run; the dashboard's link opens that one run; a user
revoked while watching loses the view. Clients are raw websockets speaking viser's protocol,
and headless Chromium for what a person sees (screenshots in tests/artifacts/)."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from html import unescape
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient
from websockets.sync.client import connect

from backend.core.config import Settings
from backend.core.viewer_tokens import issue, sign
from backend.db.arrays import pack_array
from backend.db.migrate import upgrade
from backend.db.models import Run, RunMap, RunTrajectory, User
from backend.db.session import session_scope
from backend.store import add_user, create_job, save_world
from frontend.viewer import ViewerApp, run_link
from mapqual.app import create_app
from tests.frontend.conftest import free_port
from tests.services import scratch_database
from tests.summaries import summary_doc
from worker.world.world import World

# the nodes a shown run puts in its client's scene (frontend.view.RunView.reset)
RUN_NODES = ("/floor", "/slam", "/gt", "/est", "/robot_gt", "/robot_est", "/nav")


def _room() -> np.ndarray:
    occ = np.zeros((80, 120), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True
    return occ


def _finished_run(s, owner_id: int, world_id: int, seed: int) -> int:
    """A done run with a straight 10 s path and a small map, written as a worker would."""
    job = create_job(
        s, owner_id=owner_id, world_id=world_id, slam="odometry", params={}, seeds=[seed]
    )
    run = s.get_one(Run, job.runs[0].id)  # the stored row, to write a worker's results on
    t = np.arange(0.0, 10.0, 0.1)
    gt = np.column_stack([1.0 + 0.3 * t, np.full_like(t, 2.0), np.zeros_like(t)])
    for kind, poses in (("gt", gt), ("est", gt + 0.02)):
        data = pack_array(np.column_stack([t, poses]))
        run.trajectories.append(RunTrajectory(kind=kind, n_poses=len(t), data=data))
    grid = np.full((80, 120), -1, np.int8)
    grid[20:60, 10:100] = 0
    run.map = RunMap(
        resolution=0.05, origin_x=0.0, origin_y=0.0, width=120, height=80, data=pack_array(grid)
    )
    run.summary = summary_doc(outcome="completed", reason=None, stop="no_frontier", coverage=0.4)
    run.status, run.outcome, run.coverage = "done", "completed", 0.4
    s.flush()
    return run.id


@pytest.fixture(scope="module")
def env():
    """Users a (owner of run_a), b (owner of run_b) and c (revoked); the viewer and the
    dashboard over one scratch PostgreSQL database."""
    with scratch_database("mapqual_viewer") as url:
        upgrade(url)
        with session_scope(url) as s:
            ids, keys = {}, {}
            for name in ("a", "b", "c"):
                user, keys[name] = add_user(s, name)
                ids[name] = user.id
            runs = {}
            for name in ("a", "b", "c"):
                w = save_world(
                    s, owner_id=ids[name], world=World.from_array(_room(), 0.05, name="room"),
                    sha256="room", source_format="image",
                )  # fmt: skip
                runs[name] = _finished_run(s, ids[name], w.id, 3)
            job_a = s.get_one(Run, runs["a"]).job_id
            s.get_one(User, ids["c"]).revoked_at = datetime.now(UTC)
        port = free_port()
        viewer_url = f"http://127.0.0.1:{port}"
        settings = Settings(DATABASE_URL=url, MAPQUAL_VIEWER_URL=viewer_url)
        dash = create_app(settings)
        # secret_key is None unless a developer's .env sets it: the key made in the database
        app = ViewerApp(url, None, "127.0.0.1", port, settings.secret_key)
        yield {
            "url": url, "app": app, "viewer_url": viewer_url, "dash": dash, "ids": ids,
            "keys": keys, "runs": runs, "job_a": job_a, "key": app.key,
        }  # fmt: skip
        app.stop()


@contextmanager
def _ws(env, path: str) -> Iterator[Any]:
    """A websocket client on `path`, as viser's page opens it: its subprotocol, then its
    camera (viser counts a client connected from its first camera message)."""
    import msgspec
    import viser
    from viser._messages import ViewerCameraMessage

    uri = f"ws://127.0.0.1:{env['app'].port}{path}"
    camera = ViewerCameraMessage(
        (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 5.0), 1.0, 0.01, 1000.0, 600, 800,
        (0.0, 0.0, 0.0), (0.0, 0.0, 1.0),
    )  # fmt: skip
    with connect(uri, subprotocols=[f"viser-v{viser.__version__}"], open_timeout=10) as ws:
        ws.send(msgspec.msgpack.encode(camera.as_serializable_dict()))
        yield ws


def _new_client(app: ViewerApp, before: set[int], timeout: float = 10.0) -> int:
    """The id of the client that connected after `before` was taken, once it is handled."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        new = (set(app.views) | set(app.refused)) - before
        if new:
            return new.pop()
        time.sleep(0.05)
    raise AssertionError("the viewer did not handle the connection")


def _known(app: ViewerApp) -> set[int]:
    return set(app.views) | set(app.refused)


def _scene_nodes(app: ViewerApp, client_id: int) -> list[str]:
    """The node names of that client's scene, as the server holds them."""
    client = app.server.get_clients()[client_id]
    return list(client.scene._handle_from_node_name)


def _run_nodes(app: ViewerApp, client_id: int) -> list[str]:
    """That client's scene nodes that show something of a run."""
    return [n for n in _scene_nodes(app, client_id) if n.startswith(RUN_NODES)]


def _gui_inputs(app: ViewerApp, client_id: int) -> int:
    """How many inputs (dropdowns, checkboxes, sliders, buttons) that client's panel has."""
    return len(app.server.get_clients()[client_id].gui._gui_input_handle_from_uuid)


def _assert_refused(env, path: str, why: str) -> None:
    app = env["app"]
    before = _known(app)
    with _ws(env, path):
        cid = _new_client(app, before)
        time.sleep(0.3)  # anything a wrong branch would add, it adds by now
        assert cid in app.refused and cid not in app.views, (path, why)
        assert why in app.refused[cid], (path, app.refused[cid])
        assert not _run_nodes(app, cid), (path, _scene_nodes(app, cid))
        assert _gui_inputs(app, cid) == 0, path  # no run chooser, no layers, no replay
        assert not app.live  # nothing subscribed for it


def test_clients_without_a_valid_link_see_no_run(env):
    key, runs, ids = env["key"], env["runs"], env["ids"]
    run_a = runs["a"]
    good = issue(key, run_a, ids["a"], 60)
    user, exp, mac = good.split(".")
    altered = f"{user}.{exp}.{mac[:10]}{'A' if mac[10] != 'A' else 'B'}{mac[11:]}"
    cases = [
        ("/", "no run link"),  # the viewer opened bare
        (f"/run/{run_a}", "no run link"),  # the old link, without a token
        (f"/run/{run_a}/", "not one of ours"),
        (f"/run/{run_a}/{altered}", "bad signature"),
        (f"/run/{run_a}/{sign(key, run_a, ids['a'], int(time.time()) - 1)}", "expired"),
        # another run's valid token on this run, and this run's token under another's id
        (f"/run/{run_a}/{issue(key, runs['b'], ids['b'], 60)}", "bad signature"),
        (f"/run/{runs['b']}/{good}", "bad signature"),
        # a token signed for b on a's run (as a forged dashboard would not give it)
        (f"/run/{run_a}/{issue(key, run_a, ids['b'], 60)}", "not user"),
        (f"/run/{runs['c']}/{issue(key, runs['c'], ids['c'], 60)}", "revoked"),
        (f"/run/{run_a}/{issue(b'another key' * 3, run_a, ids['a'], 60)}", "bad signature"),
    ]
    for path, why in cases:
        _assert_refused(env, path, why)


def test_a_valid_link_shows_that_run_only(env):
    app, run_a = env["app"], env["runs"]["a"]
    before = _known(app)
    with _ws(env, f"/run/{run_a}/{issue(env['key'], run_a, env['ids']['a'], 60)}"):
        cid = _new_client(app, before)
        view = app.views[cid]
        deadline = time.monotonic() + 10
        while view.mode != "replay" and time.monotonic() < deadline:
            time.sleep(0.05)
        d = view.describe()
        assert d["run"] == run_a and d["mode"] == "replay" and d["floorplan"]
        assert d["gt_points"] == 100 and d["map_tiles"] > 0
        assert any(n.startswith("/gt") for n in _run_nodes(app, cid))
        assert f"Run #{run_a}" in view.metrics.content
        # a panel without a run chooser: 7 layer boxes, Play, speed, the time slider, follow
        # robot and the top-down view
        assert _gui_inputs(app, cid) == 12


def test_a_user_revoked_while_watching_loses_the_view(env):
    app, url = env["app"], env["url"]
    with session_scope(url) as s:
        d, _ = add_user(s, "d")
        w = save_world(
            s, owner_id=d.id, world=World.from_array(_room(), 0.05, name="room"),
            sha256="room", source_format="image",
        )  # fmt: skip
        run_d, d_id = _finished_run(s, d.id, w.id, 5), d.id
    before = _known(app)
    with _ws(env, f"/run/{run_d}/{issue(env['key'], run_d, d_id, 60)}"):
        cid = _new_client(app, before)
        assert cid in app.views
        with session_scope(url) as s:
            s.get_one(User, d_id).revoked_at = datetime.now(UTC)
        deadline = time.monotonic() + 10  # within the viewer's poll (2 s)
        while cid in app.views and time.monotonic() < deadline:
            time.sleep(0.1)
        assert cid not in app.views and "ended" in app.refused[cid]
        assert not _run_nodes(app, cid), _scene_nodes(app, cid)
        assert _gui_inputs(app, cid) == 0


def _job_page_links(env, who: str) -> list[str]:
    client = TestClient(env["dash"])
    r = client.get(f"/jobs/{env['job_a']}", headers={"Authorization": f"Bearer {env['keys'][who]}"})
    assert r.status_code == 200, r.text
    return [unescape(h) for h in re.findall(r'<a class="viewer-link" href="([^"]+)"', r.text)]


def test_the_dashboards_link_opens_the_run_in_chromium(env, browser, artifacts):
    app, run_a = env["app"], env["runs"]["a"]
    (link,) = _job_page_links(env, "a")
    prefix = run_link(env["viewer_url"], run_a, "")
    assert prefix == f"{env['viewer_url']}/?websocket=ws://127.0.0.1:{app.port}/run/{run_a}/"
    assert link.startswith(prefix) and len(link) > len(prefix) + 40
    context = browser.new_context(viewport={"width": 1200, "height": 800})
    page = context.new_page()

    # the viewer opened without a link: a note, and an empty scene
    before = _known(app)
    page.goto(env["viewer_url"] + "/")
    cid = _new_client(app, before, 30)
    page.get_by_text("No run to show").wait_for(timeout=30000)
    assert cid in app.refused and not _run_nodes(app, cid)
    page.wait_for_timeout(1000)
    page.screenshot(path=artifacts / "viewer-no-link.png")

    # the dashboard's link: the run, replayed from the database
    before = _known(app)
    page.goto(link)
    cid = _new_client(app, before, 30)
    assert cid in app.views
    page.get_by_text(f"Run #{run_a}").first.wait_for(timeout=30000)
    assert page.get_by_text("No run to show").count() == 0
    assert app.views[cid].describe()["run"] == run_a
    page.wait_for_timeout(1000)
    page.screenshot(path=artifacts / "viewer-linked.png")
    context.close()


def test_the_job_page_gives_fresh_accepted_tokens_to_its_owner_only(env):
    app = env["app"]
    first = _job_page_links(env, "a")
    time.sleep(1.1)  # the expiry has one-second steps
    assert _job_page_links(env, "a") != first  # a fresh token per page
    # another owner's page answers 404, so b never holds a link to a's run
    r = TestClient(env["dash"]).get(
        f"/jobs/{env['job_a']}", headers={"Authorization": f"Bearer {env['keys']['b']}"}
    )
    assert r.status_code == 404
    path = first[0].split("?websocket=ws://", 1)[1].split("/", 1)[1]
    before = _known(app)
    with _ws(env, "/" + path):
        assert _new_client(app, before) in app.views


def test_no_client_can_open_a_public_share_tunnel(env):
    import msgspec
    from viser._messages import ShareUrlRequest

    app = env["app"]
    before = _known(app)
    with _ws(env, "/") as ws:
        _new_client(app, before)
        ws.send(msgspec.msgpack.encode(ShareUrlRequest().as_serializable_dict()))
        time.sleep(1.0)  # the request is handled on viser's thread pool
        assert app.server._share_tunnel is None


def test_a_link_that_cannot_be_checked_shows_no_run(env):
    """The database unreachable (a closed port) while a page connects: refused, not shown."""
    app, run_a = env["app"], env["runs"]["a"]
    token = issue(env["key"], run_a, env["ids"]["a"], 60)
    url, app.url = app.url, "postgresql+psycopg://postgres@127.0.0.1:1/none"
    try:
        _assert_refused(env, f"/run/{run_a}/{token}", "could not be checked")
    finally:
        app.url = url
