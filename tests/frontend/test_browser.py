"""The dashboard and the viewer in headless Chromium, over a real Celery worker, Redis and
PostgreSQL: upload a world through the form, submit a job, watch it run to done, open the job
page and the viewer, and check that the viewer's scene holds the map, both paths and the
robots while the run is live; add a bundled world from the worlds page. Screenshots go to
tests/artifacts/."""

from __future__ import annotations

import io
import re
import time
from pathlib import Path

import numpy as np
from PIL import Image

from tests.frontend.test_pages import rooms

LIVE_TIMEOUT_S = 60.0
PAGE_TIMEOUT_MS = 90_000  # [ms] any one page action (see _new_context)
WORLDS = Path(__file__).resolve().parents[2] / "worlds"


def _wait(predicate, timeout: float, what: str, step: float = 0.2):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(step)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


def _new_context(browser):
    """A 1400 px wide context whose waits allow for a loaded machine: these tests check what
    the pages show, not how fast (CI shares 2 cores with Chromium's software WebGL, the
    Celery worker and the servers; a page load there once took over Playwright's 30 s)."""
    context = browser.new_context(viewport={"width": 1400, "height": 900})
    context.set_default_timeout(PAGE_TIMEOUT_MS)
    context.set_default_navigation_timeout(PAGE_TIMEOUT_MS)
    return context


def _sign_in(page, site) -> None:
    page.goto(site.url + "/")
    assert "/login" in page.url
    page.fill('input[name="key"]', site.service.key)
    page.click('button:has-text("Sign in")')
    page.wait_for_url(site.url + "/")
    # the session cookie is Secure (cookie_secure's default) and Chromium keeps it on
    # http://127.0.0.1, a loopback origin it trusts as it would https; the key is not in it
    (cookie,) = [c for c in page.context.cookies() if c["name"] == "mapqual_session"]
    assert cookie["secure"] and cookie["httpOnly"] and cookie["sameSite"] == "Lax"
    assert site.service.key not in cookie["value"]


def _upload_world(page, site, tmp_path, artifacts) -> int:
    png = tmp_path / "rooms.png"
    Image.fromarray(np.where(rooms(5, 3), 0, 255).astype(np.uint8)).save(png)
    page.goto(site.url + "/worlds")
    page.set_input_files('input[name="file"]', str(png))
    page.fill('input[name="resolution"]', "0.05")
    page.click('button:has-text("Upload")')
    notice = page.locator(".notice").inner_text()
    world_id = int(re.search(r"as #(\d+)", notice).group(1))
    thumb = f"document.querySelector('#world-{world_id} img')"
    # the thumbnail appears once the world is analysed (the page reloads itself until then)
    page.wait_for_function(f"{thumb} && {thumb}.complete && {thumb}.naturalWidth > 0")
    # the floorplan's 601 x 361 px reduced by 2 (ceil(601 / 480)) for the thumbnail
    assert page.evaluate(f"[{thumb}.naturalWidth, {thumb}.naturalHeight]") == [301, 181]
    page.screenshot(path=artifacts / "worlds.png", full_page=True)
    return world_id


def _shoot(page, path) -> None:
    """A screenshot without the software-WebGL notice that headless Chromium triggers."""
    close = page.locator(".mantine-Notification-closeButton")
    for i in range(close.count()):
        close.nth(i).click()
    page.wait_for_timeout(700)  # the notice fades out
    page.screenshot(path=path)


def _live_scene(site, run_id: int) -> dict:
    """The viewer's scene of a client watching `run_id` live, once it holds everything."""

    def ready():
        for view in list(site.viewer.views.values()):
            d = view.describe()
            if d.get("run") == run_id and d.get("mode") == "live":
                full = d["map_tiles"] > 0 and d["gt_points"] >= 3 and d["est_points"] >= 3
                if full and d["robot_gt"] and d["robot_est"] and d["floorplan"]:
                    return d
        return None

    return _wait(ready, LIVE_TIMEOUT_S, f"the viewer's live scene of run {run_id}")


def _submit_one_run(page, site, world_id: int) -> tuple[int, int]:
    """Submit a job of one 90 s rbpf run on the world from the jobs page: (job id, run id)."""
    page.goto(site.url + "/")
    page.select_option('select[name="world_id"]', str(world_id))
    page.fill('input[name="runs"]', "1")
    page.select_option('select[name="slam"]', "rbpf")
    page.fill('input[name="time_limit"]', "90")
    page.click('button:has-text("Submit")')
    page.wait_for_url(re.compile(r".*/jobs/\d+$"))
    job_id = int(page.url.rsplit("/", 1)[1])
    return job_id, int(page.locator("tr[data-run]").first.get_attribute("data-run"))


def _replay_from_the_start(viewer, site, run_id: int, replay: dict) -> None:
    """Play at the end starts the replay over: the time slider runs and the paths regrow."""
    view = next(v for v in site.viewer.views.values() if v.run_id == run_id)
    end = view.slider.max
    viewer.get_by_role("button", name="Play").click()
    _wait(lambda: view.playing and 0 < view.slider.value < end, 30, "the replay to play")
    assert view.describe()["gt_points"] < replay["gt_points"]
    _wait(lambda: view.slider.value > 3.0, 30, "the replay to advance")


def test_upload_submit_watch_live_and_browse_results(browser, site, tmp_path, artifacts):
    context = _new_context(browser)
    page = context.new_page()
    _sign_in(page, site)
    world_id = _upload_world(page, site, tmp_path, artifacts)
    job_id, run_id = _submit_one_run(page, site, world_id)

    # the run page's link opens the viewer on this run while it is live
    running = f'tr[data-run="{run_id}"][data-status="running"]'
    _wait(lambda: page.goto(page.url) and page.locator(running).count(), 30, "the run to start")
    with context.expect_page() as new:
        page.click(f'tr[data-run="{run_id}"] a.viewer-link')
    viewer = new.value
    scene = _live_scene(site, run_id)
    assert scene["scan"] and viewer.url.startswith(site.viewer_url)
    # the metrics panel in the page shows the run and its simulated time
    viewer.get_by_text(f"Run #{run_id}").first.wait_for()
    assert viewer.get_by_text("sim time").count() >= 1
    time.sleep(1.0)  # let the browser draw what it received
    _shoot(viewer, artifacts / "viewer-live.png")
    page.screenshot(path=artifacts / "job-running.png", full_page=True)

    # the jobs list refreshes by itself until the job is done
    page.goto(site.url + "/")
    done = f'tr[data-job="{job_id}"][data-status="done"]'
    _wait(lambda: page.locator(done).count() or page.wait_for_timeout(500), 120, "job done")
    assert page.locator(f'tr[data-job="{job_id}"] progress').get_attribute("value") == "100"
    page.screenshot(path=artifacts / "jobs.png", full_page=True)

    page.goto(f"{site.url}/jobs/{job_id}")
    images = page.locator(f"#run-{run_id} img")
    assert images.count() == 4  # trajectories, errors, the map, the map over the floorplan
    page.wait_for_function(
        f"Array.from(document.querySelectorAll('#run-{run_id} img'))"
        ".every(i => i.complete && i.naturalWidth > 0)"
    )
    page.screenshot(path=artifacts / "job.png", full_page=True)

    # the viewer turns the finished run into a replay from the database
    replay = _wait(
        lambda: next(
            (v.describe() for v in site.viewer.views.values() if v.mode == "replay"), None
        ),
        15,
        "the viewer's replay",
    )
    assert replay["run"] == run_id and replay["gt_points"] > scene["gt_points"]
    time.sleep(1.0)
    _shoot(viewer, artifacts / "viewer-replay.png")
    _replay_from_the_start(viewer, site, run_id, replay)

    page.goto(site.url + "/compare")
    assert page.locator("#compare-table tbody tr").count() == 1
    page.screenshot(path=artifacts / "compare.png", full_page=True)
    for name in ("worlds", "viewer-live", "job-running", "jobs", "job", "viewer-replay"):
        shot = Image.open(io.BytesIO((artifacts / f"{name}.png").read_bytes()))
        assert shot.size[0] == 1400, name
    context.close()


def test_the_bundled_data_sets_on_the_worlds_page(browser, site, artifacts):
    context = _new_context(browser)
    page = context.new_page()
    _sign_in(page, site)
    page.goto(site.url + "/worlds")
    stems = sorted(p.stem for p in (WORLDS / "schools").glob("*.yaml"))
    summary = page.locator("#dataset-schools summary")
    assert f"{len(stems)} worlds" in summary.inner_text()
    imgs = "Array.from(document.querySelectorAll('#dataset-schools img'))"
    # closed, the section's lazy thumbnails are not fetched; open, the visible ones are
    assert page.evaluate(f"{imgs}.every(i => i.naturalWidth === 0)")
    summary.click()
    page.wait_for_function(f"{imgs}.slice(0, 6).every(i => i.complete && i.naturalWidth > 0)")
    assert page.evaluate(f"{imgs}.length") == len(stems)
    page.locator('#dataset-schools [data-world="Borchen4"] button').click()
    notice = page.locator(".notice").inner_text()
    world_id = int(re.search(r"'Borchen4' added to your worlds as #(\d+)", notice).group(1))
    thumb = f"document.querySelector('#world-{world_id} img')"
    page.wait_for_function(f"{thumb} && {thumb}.complete && {thumb}.naturalWidth > 0")
    page.locator("#dataset-schools summary").click()
    card = page.locator('#dataset-schools [data-world="Borchen4"]')
    card.scroll_into_view_if_needed()
    assert card.locator(".in-mine").inner_text() == f"in your worlds as #{world_id}"
    page.wait_for_function(f"{imgs}.slice(0, 6).every(i => i.complete && i.naturalWidth > 0)")
    page.screenshot(path=artifacts / "worlds-bundled.png", full_page=True)
    page.goto(site.url + "/")
    assert page.locator(f'select[name="world_id"] option[value="{world_id}"]').count() == 1
    context.close()
