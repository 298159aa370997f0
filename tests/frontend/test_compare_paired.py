"""The compare page's algorithms side by side and their paired comparison, over a real database
holding runs stored as the worker stores them (store_run_result)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from fastapi.testclient import TestClient
from scipy import stats

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user, create_job, mark_run_started, save_world, store_run_result
from mapqual.app import create_app
from tests.frontend.test_pages import rooms
from tests.services import ensure_redis
from tests.summaries import make_summary, relation
from tests.summaries import stats as rel_stats
from worker.world.world import World

# mean B translational error [m] of each stored run, by algorithm and seed
ERRORS = {
    "graph": {1: 0.11, 2: 0.14, 3: 0.09, 4: 0.30},
    "rbpf": {1: 0.25, 2: 0.26, 3: 0.22, 4: None},  # seed 4 failed (a collision)
}


def _store(s, owner: int, world: int, slam: str) -> None:
    job = create_job(s, owner_id=owner, world_id=world, slam=slam, params={},
                     seeds=list(ERRORS[slam]))  # fmt: skip
    for run in job.runs:
        err = ERRORS[slam][run.seed]
        if err is None:
            summary = make_summary(outcome="failed", reason="collision", stop="collision",
                                   relations={})  # fmt: skip
        else:
            b = relation(rel_stats(err, 0.05, 200), rel_stats(0.01, 0.005, 200))
            summary = make_summary(outcome="completed", reason=None, stop="no_frontier",
                                   relations={"B": b})  # fmt: skip
        mark_run_started(s, run.id)
        t = np.arange(3.0)
        store_run_result(
            s, run.id, summary=summary, t=t, pose_gt=np.zeros((3, 3)), pose_est=np.zeros((3, 3)),
            map_ros=np.zeros((4, 4), np.int8), map_resolution=0.05, map_origin=(0.0, 0.0),
            report_dir=None,
        )  # fmt: skip


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    url = f"sqlite:///{tmp_path_factory.mktemp('compare') / 'compare.db'}"
    upgrade(url)
    world = World.from_array(rooms(), 0.05, name="rooms")
    with session_scope(url) as s:
        a, key = add_user(s, "a")
        w = save_world(s, owner_id=a.id, world=world, sha256="rooms", source_format="image")
        for slam in ERRORS:
            _store(s, a.id, w.id, slam)
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/15"
    app = create_app(Settings(DATABASE_URL=url, REDIS_URL=redis_url))
    c = TestClient(app, base_url="https://testserver")
    c.headers["Authorization"] = f"Bearer {key}"
    return c


def _rows(page: str, table_id: str) -> list[list[str]]:
    body = page.split(f'id="{table_id}"', 1)[1].split("</table>", 1)[0]
    rows = re.findall(r"<tr>(.*?)</tr>", body.split("<tbody>", 1)[1], re.S)
    return [[re.sub(r"<[^>]+>", "", c).strip() for c in re.findall(r"<td[^>]*>(.*?)</td>", r, re.S)]
            for r in rows]  # fmt: skip


def test_compare_page_shows_algorithms_side_by_side_with_a_paired_interval(client):
    r = client.get("/compare")
    assert r.status_code == 200, r.text
    side = _rows(r.text, "slam-table")
    # graph: 4 runs, all completed, mean of 0.11 0.14 0.09 0.30; rbpf: 4 runs, 3 completed
    assert side == [["rooms", "graph", "4", "4", "0.160", "4", "0"],
                    ["rooms", "rbpf", "4", "3", "0.243", "3", "0"]]  # fmt: skip
    (paired,) = _rows(r.text, "paired-table")
    # seeds 1-3 paired (rbpf failed on 4): differences -0.14, -0.12, -0.13
    g = np.array([0.11, 0.14, 0.09])
    b = np.array([0.25, 0.26, 0.22])
    ci = stats.ttest_rel(g, b).confidence_interval(0.95)
    assert paired[:4] == ["rooms", "graph", "rbpf", "3"]
    assert paired[4:7] == ["0.113", "0.243", f"{np.mean(g - b):+.3f}"]
    assert paired[7] == f"[{ci.low:+.3f}, {ci.high:+.3f}]"
    assert ci.high < 0 and paired[8:] == ["3 of 3", "graph lower"]


def test_paired_chart_is_a_png(client):
    r = client.get("/compare/paired.png")
    assert r.status_code == 200 and r.content[:4] == b"\x89PNG"
    assert client.get("/compare/nonsense.png").status_code == 404
