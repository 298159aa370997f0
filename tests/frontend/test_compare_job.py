"""A job that compares: submitted with two algorithms and an explicit seed list (over the API
and through the form), its runs stored as the worker stores them; in Chromium its page leads
with the paired comparison, whose numbers must be the paired t-interval computed here."""

from __future__ import annotations

import re

import numpy as np
import pytest
from scipy import stats

from backend.db.models import Run
from backend.db.session import session_scope
from backend.store import add_user, mark_run_started, save_world, store_run_result
from tests.frontend.test_explore import serve
from tests.frontend.test_pages import rooms
from tests.summaries import make_summary, relation
from tests.summaries import stats as rel_stats
from worker.world.world import World

SEEDS = [2, 3, 5, 8]
ERRORS = {"graph": {2: 0.12, 3: 0.10, 5: 0.15, 8: 0.11},  # seed 5: stopped by its time limit
          "rbpf": {2: 0.21, 3: 0.24, 5: 0.19, 8: 0.26}}  # fmt: skip


def _finish(url: str, run_ids: list[int]) -> None:
    with session_scope(url) as s:
        for rid in run_ids:
            run = s.get(Run, rid)
            err = ERRORS[run.slam][run.seed]
            limit = run.slam == "graph" and run.seed == 5
            summary = make_summary(
                outcome="failed" if limit else "completed", reason="time_limit" if limit else None,
                stop="time_limit" if limit else "no_frontier",
                relations={"B": relation(rel_stats(err, 0.05, 200), rel_stats(0.01, 0.005, 200))},
            )  # fmt: skip
            mark_run_started(s, rid)
            store_run_result(
                s, rid, summary=summary, t=np.arange(3.0), pose_gt=np.zeros((3, 3)),
                pose_est=np.zeros((3, 3)), map_ros=np.zeros((4, 4), np.int8),
                map_resolution=0.05, map_origin=(0.0, 0.0), report_dir=None,
            )  # fmt: skip


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    url = f"sqlite:///{tmp_path_factory.mktemp('cmpjob') / 'cmpjob.db'}"

    def fill(s):
        a, key = add_user(s, "a")
        w = save_world(s, owner_id=a.id, world=World.from_array(rooms(), 0.05, name="rooms"),
                       sha256="rooms", source_format="image")  # fmt: skip
        return key, w.id

    with serve(url, fill) as (base, (key, world_id)):
        yield url, base, key, world_id


def test_a_two_algorithm_job_leads_with_its_paired_comparison(browser, site, artifacts):
    url, base, key, world_id = site
    auth = {"Authorization": f"Bearer {key}"}
    context = browser.new_context(viewport={"width": 1400, "height": 900}, extra_http_headers=auth)
    context.set_default_timeout(90_000)
    body = {"world_id": world_id, "algorithms": ["graph", "rbpf"], "seeds": SEEDS,
            "params": {"explore": {"time_limit": 300}}}  # fmt: skip
    r = context.request.post(base + "/api/v1/jobs", data=body)
    assert r.status == 202, r.text()
    job = r.json()
    runs = {(x["slam"], x["seed"]) for x in job["runs"]}
    assert runs == {(a, s) for a in ERRORS for s in SEEDS} and job["slam"] == "graph+rbpf"
    bad = context.request.post(base + "/api/v1/jobs", data={**body, "slam": "rbpf"})
    assert bad.status == 422 and "not both" in bad.text()
    _finish(url, [x["id"] for x in job["runs"]])

    page = context.new_page()
    page.goto(f"{base}/jobs/{job['id']}")
    heading = page.locator("#job-comparison")
    assert heading.inner_text() == "graph vs rbpf on the same seeds"
    assert "time limit 300 s" in page.locator("#job-settings").inner_text()
    cells = [c.strip() for c in page.locator("#paired-table tbody tr").first.locator("td")
             .all_inner_texts()]  # fmt: skip
    g = np.array([ERRORS["graph"][s] for s in SEEDS])  # the time-limited run counts, scored
    b = np.array([ERRORS["rbpf"][s] for s in SEEDS])
    ci = stats.ttest_rel(g, b).confidence_interval(0.95)
    assert cells[:4] == ["time_limit=300", "graph", "rbpf", "4"]
    assert cells[4:7] == [f"{g.mean():.3f}", f"{b.mean():.3f}", f"{np.mean(g - b):+.3f}"]
    assert cells[7] == f"[{ci.low:+.3f}, {ci.high:+.3f}]"
    assert cells[8:] == ["4 of 4", "graph lower"]
    # the comparison comes before the runs
    box = page.locator("#job-comparison").bounding_box()
    assert box["y"] < page.locator("table.runs").bounding_box()["y"]
    page.screenshot(path=artifacts / "job-compare.png", full_page=True)

    # the form: two algorithms picked, an explicit seed list
    page.goto(base + "/")
    page.select_option('select[name="world_id"]', str(world_id))
    page.select_option('select[name="slam"]', ["graph", "rbpf"])
    page.fill('input[name="seeds"]', "4-5, 9")
    page.click('button:has-text("Submit")')
    page.wait_for_url(re.compile(r".*/jobs/\d+$"))
    new = int(page.url.rsplit("/", 1)[1])
    with session_scope(url) as s:
        got = sorted((r.slam, r.seed) for r in s.query(Run).filter(Run.job_id == new))
    assert got == sorted((a, s) for a in ("graph", "rbpf") for s in (4, 5, 9))
    page.goto(base + "/")
    page.select_option('select[name="world_id"]', str(world_id))
    page.fill('input[name="seeds"]', "9-3")  # the form's pattern lets it through
    page.click('button:has-text("Submit")')
    assert "the range '9-3' is empty or too long" in page.locator(".error").inner_text()
    context.close()
