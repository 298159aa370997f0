"""The manual's screenshots of the viewer and the results explorer, made on the real service
(PostgreSQL, Redis, a Celery worker, headless Chromium): office_a, an asymmetric building, run
by two algorithms on the same seeds in one comparison job; the viewer live, looking back during
the run, and in replay half-way; the job page, the explorer and its zoom view.

    python -m tests.frontend.docs_screenshots docs/img   (needs PostgreSQL and redis-server)
"""

from __future__ import annotations

import re
import sys
import tempfile
import time
from pathlib import Path

import tests.frontend.test_browser as tb
from tests.frontend.conftest import CHROMIUM_ARGS, OwnRedis, Site, browser_service, chromium_path
from tests.frontend.test_browser import _live_scene, _new_context, _shoot, _sign_in, _wait
from tests.frontend.test_viewer_timeline import _slide_to

WORLD = ("bormann", "office_a")
SECONDS = 60  # [s] simulated per run: a map with a few rooms, on a shared machine


def _add_world(page, site) -> int:
    page.goto(site.url + "/worlds")
    summary = page.locator(f"#dataset-{WORLD[0]} summary")
    summary.click()
    page.locator(f'#dataset-{WORLD[0]} [data-world="{WORLD[1]}"] button').click()
    notice = page.locator(".notice").inner_text()
    world_id = int(re.search(r"as #(\d+)", notice).group(1))
    thumb = f"document.querySelector('#world-{world_id} img')"
    page.wait_for_function(f"{thumb} && {thumb}.complete && {thumb}.naturalWidth > 0")
    return world_id


def _submit(page, site, world_id: int, slams: list[str], seeds: str) -> int:
    page.goto(site.url + "/")
    page.select_option('select[name="world_id"]', str(world_id))
    page.fill('input[name="seeds"]', seeds)
    page.select_option('select[name="slam"]', slams)
    page.fill('input[name="time_limit"]', str(SECONDS))
    page.click('button:has-text("Submit")')
    page.wait_for_url(re.compile(r".*/jobs/\d+$"))
    return int(page.url.rsplit("/", 1)[1])


def _viewer(context, page, site, out: Path) -> None:
    run_id = int(page.locator("tr[data-run]").first.get_attribute("data-run"))
    running = f'tr[data-run="{run_id}"][data-status="running"]'
    _wait(lambda: page.goto(page.url) and page.locator(running).count(), 120, "the run to start")
    with context.expect_page() as new:
        page.click(f'tr[data-run="{run_id}"] a.viewer-link')
    viewer = new.value
    viewer.set_viewport_size({"width": 1400, "height": 900})
    _live_scene(site, run_id)
    time.sleep(20.0)  # a map with a few rooms in it
    _shoot(viewer, out / "viewer-live.png")
    _slide_to(viewer, 0.35)  # back in time while the run goes on
    viewer.get_by_text("looking back").first.wait_for()
    time.sleep(3.0)
    _shoot(viewer, out / "viewer-live-back.png")
    viewer.get_by_role("button", name="Back to live").click()
    _wait(
        lambda: any(v.mode == "replay" for v in site.viewer.views.values()),
        900,
        "the replay",
        step=2.0,
    )
    time.sleep(3.0)
    _slide_to(viewer, 0.5)  # half-way: the figures of that moment
    time.sleep(3.0)
    _shoot(viewer, out / "viewer-replay.png")


def _results(page, site, out: Path, job_id: int) -> None:
    done = f'tr[data-job="{job_id}"][data-status="done"]'
    _wait(lambda: page.goto(site.url + "/") and page.locator(done).count(), 1800, "jobs done", 5)
    page.screenshot(path=out / "jobs.png", full_page=True)
    page.goto(f"{site.url}/jobs/{job_id}")
    page.wait_for_timeout(3000)
    # the page's head: the comparison it leads with, the summary plot and the runs table
    clip = {"x": 0, "y": 0, "width": 1400, "height": 1760}
    page.screenshot(path=out / "job-compare.png", full_page=True, clip=clip)
    page.goto(f"{site.url}/explore")
    page.wait_for_function(
        "Array.from(document.querySelectorAll('#comparison img'))"
        ".every(i => i.complete && i.naturalWidth > 0)"
    )
    page.screenshot(path=out / "explorer.png", full_page=True)
    page.locator("#plot-paths img").click()
    page.wait_for_function("document.querySelector('#zoom-view').dataset.loaded === '1'")
    box = page.locator("#zoom-view .zoom-stage").bounding_box()
    page.mouse.move(box["x"] + 0.3 * box["width"], box["y"] + 0.5 * box["height"])
    page.mouse.wheel(0, -300)
    page.wait_for_timeout(500)
    page.screenshot(path=out / "explorer-zoom.png")


def main(out: Path) -> None:
    from playwright.sync_api import sync_playwright

    out.mkdir(parents=True, exist_ok=True)
    tb.LIVE_TIMEOUT_S = 600.0  # a shared machine: the first map of a big building takes a while
    redis = OwnRedis()
    service = browser_service(Path(tempfile.mkdtemp()), redis.url)
    site = Site(service)
    try:
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
            context = _new_context(browser)
            page = context.new_page()
            _sign_in(page, site)
            world_id = _add_world(page, site)
            job = _submit(page, site, world_id, ["rbpf", "graph"], "1-2")
            page.goto(f"{site.url}/jobs/{job}")
            _viewer(context, page, site, out)
            _results(page, site, out, job)
            browser.close()
    finally:
        site.stop()
        service.stop()
        redis.stop()


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "docs/img"))
