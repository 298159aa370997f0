"""The results explorer in headless Chromium over runs stored as the worker stores them: two
algorithms x two settings (default time limit, and 400 s) x 4 seeds, some stopped by their time
limit (scored) and one by a collision. Filtering and grouping must give the numbers computed
here, independently, from the runs' own scores."""

from __future__ import annotations

import contextlib
import csv
import io
import re
import threading
import time

import numpy as np
import pytest
from scipy import stats

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.session import session_scope
from backend.store import add_user, create_job, mark_run_started, save_world, store_run_result
from mapqual.app import create_app
from tests.frontend.conftest import free_port
from tests.frontend.test_pages import rooms
from tests.services import ensure_redis
from tests.summaries import make_summary, relation
from tests.summaries import stats as rel_stats
from worker.run_params import RunParams
from worker.world.world import World

# (algorithm, setting) -> seed -> (outcome, reason, mean B translational error [m] or None)
RUNS = {
    ("graph", "defaults"): {1: ("completed", None, 0.11), 2: ("completed", None, 0.14),
                            3: ("failed", "time_limit", 0.09), 4: ("completed", None, 0.30)},
    ("graph", "time_limit=400"): {1: ("completed", None, 0.10), 2: ("completed", None, 0.12),
                                  3: ("completed", None, 0.13), 4: ("completed", None, 0.16)},
    ("rbpf", "defaults"): {1: ("completed", None, 0.25), 2: ("failed", "time_limit", 0.26),
                           3: ("completed", None, 0.22), 4: ("failed", "collision", None)},
    ("rbpf", "time_limit=400"): {1: ("completed", None, 0.21), 2: ("completed", None, 0.24),
                                 3: ("failed", "time_limit", 0.20), 4: ("completed", None, 0.27)},
}  # fmt: skip


def _params(slam: str, setting: str) -> dict:
    p = RunParams(algorithm=slam).to_json()  # type: ignore[arg-type]
    if setting != "defaults":
        p["explore"]["time_limit"] = 400.0
    return p


def _store(s, owner: int, world: int, slam: str, setting: str) -> None:
    runs = RUNS[(slam, setting)]
    job = create_job(s, owner_id=owner, world_id=world, slam=slam,
                     params=_params(slam, setting), seeds=list(runs))  # fmt: skip
    for run in job.runs:
        outcome, reason, err = runs[run.seed]
        rels = {} if err is None else {"B": relation(rel_stats(err, 0.05, 200),
                                                     rel_stats(0.01, 0.005, 200))}  # fmt: skip
        stop = reason or "no_frontier"
        summary = make_summary(outcome=outcome, reason=reason, stop=stop, relations=rels)
        mark_run_started(s, run.id)
        t = np.arange(3.0)
        gt = np.column_stack((t, t, np.zeros(3)))
        store_run_result(
            s, run.id, summary=summary, t=t, pose_gt=gt, pose_est=gt + [0.0, 0.1, 0.0],
            map_ros=np.zeros((4, 4), np.int8), map_resolution=0.05, map_origin=(0.0, 0.0),
            report_dir=None,
        )  # fmt: skip


@contextlib.contextmanager
def serve(url: str, fill):
    """The dashboard on a real uvicorn server over a fresh database that `fill(session)`
    stocked; yields (base URL, what fill returned)."""
    import uvicorn

    upgrade(url)
    with session_scope(url) as s:
        made = fill(s)
    redis_url = ensure_redis().rsplit("/", 1)[0] + "/15"
    port = free_port()
    app = create_app(Settings(DATABASE_URL=url, REDIS_URL=redis_url))
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    th = threading.Thread(target=server.run, daemon=True)
    th.start()
    while not server.started:
        time.sleep(0.05)
    try:
        yield f"http://127.0.0.1:{port}", made
    finally:
        server.should_exit = True
        th.join(timeout=10)


@pytest.fixture(scope="module")
def dashboard(tmp_path_factory):
    def fill(s):
        a, key = add_user(s, "a")
        w = save_world(s, owner_id=a.id, world=World.from_array(rooms(), 0.05, name="rooms"),
                       sha256="rooms", source_format="image")  # fmt: skip
        for slam, setting in RUNS:
            _store(s, a.id, w.id, slam, setting)
        return key

    with serve(f"sqlite:///{tmp_path_factory.mktemp('explore') / 'explore.db'}", fill) as (
        base,
        key,
    ):
        yield base, key


def expected(slam: str, setting: str | None, kinds: set[str]) -> dict:
    """n, mean, sample std and t-based 95 % interval of the B errors of the runs kept."""
    vals = []
    for (sl, st), runs in RUNS.items():
        if sl != slam or (setting is not None and st != setting):
            continue
        for outcome, reason, err in runs.values():
            kind = outcome if outcome == "completed" else ("time limit" if reason == "time_limit"
                                                           else "failed")  # fmt: skip
            if kind in kinds and err is not None:
                vals.append(err)
    v = np.array(vals)
    half = stats.t.ppf(0.975, len(v) - 1) * v.std(ddof=1) / np.sqrt(len(v))
    return {"n": len(v), "mean": v.mean(), "std": v.std(ddof=1), "ci": (v.mean() - half,
                                                                      v.mean() + half)}  # fmt: skip


def _b_cell(page, ident: str) -> tuple[int, str]:
    cell = page.locator(f'#groups-table tr[data-group="{ident}"] td[data-score="b_t"]')
    return int(cell.get_attribute("data-n")), " ".join(cell.inner_text().split())


def _fmt(e: dict) -> str:
    return f"{e['mean']:.3f} ± {e['std']:.3f} [{e['ci'][0]:.3f}, {e['ci'][1]:.3f}]"


def _explore(browser, dashboard):
    """(base URL, browser context, page on /explore) signed in by the key header."""
    base, key = dashboard
    auth = {"Authorization": f"Bearer {key}"}
    context = browser.new_context(viewport={"width": 1400, "height": 900}, extra_http_headers=auth)
    context.set_default_timeout(90_000)
    page = context.new_page()
    page.goto(base + "/explore")
    return base, context, page


def test_the_explorer_filters_groups_and_compares(browser, dashboard, artifacts):
    base, context, page = _explore(browser, dashboard)
    # by default time-limited runs count with their scores; the collision (no scores) does not
    kinds = {"completed", "time limit"}
    assert page.locator("#groups-table tbody tr").count() == 4
    for slam, setting in RUNS:
        n, text = _b_cell(page, f"rooms|{slam}|{setting}")
        e = expected(slam, setting, kinds)
        assert (n, text) == (e["n"], _fmt(e)), (slam, setting)
    tl = page.locator('#runs-table tr[data-kind="time limit"]')
    assert tl.count() == 3 and "time limit, scored" in tl.first.inner_text()
    # the paired comparison of the selection: graph against rbpf on each setting's seeds
    paired = page.locator("#paired-table tbody tr")
    assert paired.count() == 3  # two settings and the pooled ALL row
    page.screenshot(path=artifacts / "explore.png", full_page=True)

    # leave the time-limited runs out, and group by algorithm alone
    page.uncheck('input[name="kind"][value="time limit"]')
    page.uncheck('input[name="by"][value="world"]')
    page.uncheck('input[name="by"][value="setting"]')
    page.click('#explore-filters button[type="submit"]')
    page.wait_for_url(re.compile(r".*applied=1.*"))
    assert page.locator("#groups-table tbody tr").count() == 2
    for slam in ("graph", "rbpf"):
        n, text = _b_cell(page, slam)
        e = expected(slam, None, {"completed"})
        assert (n, text) == (e["n"], _fmt(e)), slam
    # success: completed / runs kept; failed runs (the collision) are left out by default, and
    # now the time-limited ones too: rbpf keeps its 5 completed runs of 8
    rate = page.locator('#groups-table tr[data-group="rbpf"] td.success')
    assert rate.inner_text().startswith("100 %")

    # the CSV holds the same groups to full precision
    csv_url = page.get_by_role("link", name="groups as CSV").get_attribute("href")
    got = context.request.get(base + csv_url)
    table = list(csv.DictReader(io.StringIO(got.text())))
    by_slam = {row["slam"]: row for row in table}
    for slam in ("graph", "rbpf"):
        e = expected(slam, None, {"completed"})
        assert float(by_slam[slam]["b_t_mean"]) == pytest.approx(e["mean"], abs=1e-12)
        assert float(by_slam[slam]["b_t_ci_low"]) == pytest.approx(e["ci"][0], abs=1e-12)
    imgs = page.locator("#comparison img")
    assert imgs.count() == 4
    for i in range(imgs.count()):
        src = imgs.nth(i).get_attribute("src")
        plot = context.request.get(base + src)
        assert plot.status == 200 and plot.headers["content-type"] == "image/png", src
        name = re.search(r"plot/(\w+)\.png", src).group(1)
        (artifacts / f"explore-{name}.png").write_bytes(plot.body())
    page.screenshot(path=artifacts / "explore-by-algorithm.png", full_page=True)
    context.close()


def test_a_plot_opens_in_a_zoom_view(browser, dashboard, artifacts):
    """A click on a comparison plot opens it over the page at twice the resolution (220 dpi
    against the page's 110), the wheel zooms about the pointer, a drag pans, the PNG and CSV
    stay downloadable from it, Esc closes it."""
    base, context, page = _explore(browser, dashboard)
    thumb = page.locator("#plot-scores img")
    thumb.scroll_into_view_if_needed()
    page.wait_for_function("document.querySelector('#plot-scores img').naturalWidth > 0")
    small = page.evaluate("document.querySelector('#plot-scores img').naturalWidth")
    thumb.click()
    view = page.locator("#zoom-view")
    page.wait_for_function("document.querySelector('#zoom-view').dataset.loaded === '1'")
    assert view.is_visible() and len(context.pages) == 1  # over the page, not a new tab
    big = page.evaluate("document.querySelector('#zoom-view img').naturalWidth")
    assert abs(big - 2 * small) <= 2, (big, small)
    img = page.locator("#zoom-view img")
    fit = img.bounding_box()
    stage = page.locator("#zoom-view .zoom-stage").bounding_box()
    assert fit["width"] <= stage["width"] + 1 and fit["height"] <= stage["height"] + 1
    cx, cy = stage["x"] + stage["width"] / 2, stage["y"] + stage["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.wheel(0, -400)
    page.wait_for_function("parseFloat(document.querySelector('#zoom-view').dataset.scale) > 2")
    zoomed = img.bounding_box()
    scale = float(view.get_attribute("data-scale"))
    assert zoomed["width"] == pytest.approx(fit["width"] * scale, rel=0.02)
    # the point under the pointer stays under it: the image grew about it
    share = (cx - fit["x"]) / fit["width"]
    assert (cx - zoomed["x"]) / zoomed["width"] == pytest.approx(share, abs=0.01)
    page.mouse.move(cx, cy)
    page.mouse.down()
    page.mouse.move(cx - 150, cy - 80, steps=5)
    page.mouse.up()
    panned = img.bounding_box()
    assert panned["x"] == pytest.approx(zoomed["x"] - 150, abs=2)
    assert panned["y"] == pytest.approx(zoomed["y"] - 80, abs=2)
    page.screenshot(path=artifacts / "explore-zoom.png")
    png = view.locator("a.zoom-png").get_attribute("href")
    csv_href = view.locator("a.zoom-csv").get_attribute("href")
    got = context.request.get(base + png)
    assert got.status == 200 and got.headers["content-type"] == "image/png"
    assert context.request.get(base + csv_href).text().startswith("run,job,world")
    page.keyboard.press("Escape")
    assert not view.is_visible()
    context.close()
