"""The viewer's instruments beside the scene: the top-down camera and following the robot, the
legend with colour swatches, the tab's title, and the pose error of the moment."""

from __future__ import annotations

import html
import json
import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from frontend.layers import (
    EST_RGB,
    FLOOR_FREE,
    FLOOR_WALL,
    GT_RGB,
    MAP_FREE_RGB,
    MAP_OCC_RGB,
    NAV_GOAL_RGB,
    NAV_PLAN_RGB,
    SCAN_RGB,
)

if TYPE_CHECKING:
    import viser

    from frontend.live import FinishedRun, RunInfo
    from worker.report.summary import RunSummary

# viser 1.1.1, the newest release (2026-12-06), has a perspective camera only: its client's
# <Canvas> is made without react-three-fiber's `orthographic` flag, its camera controls read
# the camera as a THREE.PerspectiveCamera (`fov`), and the Python CameraHandle offers fov,
# position, look_at, up, near and far, no projection or zoom. A narrow field of view seen
# from high above is as near orthographic as it gets: 1 % of scale change from the floor to
# a robot 5 cm above it, seen from a few metres, and no tilt.
TOP_DOWN_FOV = math.radians(20.0)
TILT = 1e-3  # [share of the height] the camera's step south: straight down has no "up"


def _floor_rgb(grey: int) -> tuple[int, int, int]:
    return (grey, grey, grey)


LEGEND_ITEMS: tuple[tuple[str, tuple[int, int, int], str], ...] = (
    ("floorplan wall", _floor_rgb(FLOOR_WALL), "square"),
    ("floorplan free", _floor_rgb(FLOOR_FREE), "square"),
    ("SLAM map: occupied", tuple(int(v) for v in MAP_OCC_RGB), "square"),
    ("SLAM map: free", tuple(int(v) for v in (FLOOR_FREE + MAP_FREE_RGB) // 2), "square"),
    ("ground truth (path, robot)", GT_RGB, "line"),
    ("SLAM estimate (path, robot)", EST_RGB, "line"),
    ("laser scan", SCAN_RGB, "dot"),
    ("frontier goal", NAV_GOAL_RGB, "dot"),
    ("global plan", NAV_PLAN_RGB, "line"),
)


def legend_html() -> str:
    """The legend: one colour swatch per thing drawn, shaped as it is drawn."""
    shapes = {
        "square": "width:14px;height:14px",
        "line": "width:18px;height:4px;margin:5px 0",
        "dot": "width:10px;height:10px;border-radius:50%;margin:2px",
    }
    rows = []
    for label, rgb, shape in LEGEND_ITEMS:
        swatch = (
            f'<span style="display:inline-block;{shapes[shape]};vertical-align:middle;'
            f'background:rgb{tuple(rgb)};border:1px solid #666"></span>'
        )
        text = html.escape(label)
        rows.append(f'<div style="margin:2px 0;font-size:0.85em">{swatch} {text}</div>')
    note = (
        '<div style="font-size:0.75em;color:#666">map_server frame: origin lower left, '
        "x right, y up; 1 grid square = 1 m</div>"
    )
    return '<div style="padding:0 0.75em">' + "".join(rows) + note + "</div>"


def title_html(title: str) -> str:
    """Sets the browser tab's title (viser's page says "Viser"): an image that fails to load
    runs its onerror, the one way viser's HTML element runs code. The title is a JSON string
    literal, HTML-escaped inside the attribute, so no name can break out of either."""
    js = f"document.title={json.dumps(title)}"
    return f'<img src="data:," alt="" style="display:none" onerror="{html.escape(js)}">'


def run_title(info: RunInfo | None) -> str:
    """The tab's title of a run: what it is, so tabs of several runs tell themselves apart."""
    if info is None:
        return "mapqual viewer"
    return f"Run #{info.id} · {info.world} · {info.slam} · seed {info.seed} — mapqual"


def pose_error(gt: ArrayLike, est: ArrayLike) -> tuple[float, float]:
    """Translational [m] and absolute rotational [rad] difference of two poses (x, y, theta):
    the estimate against the ground truth in the frame both are drawn in, without alignment."""
    dx, dy = float(est[0]) - float(gt[0]), float(est[1]) - float(gt[1])
    dth = (float(est[2]) - float(gt[2]) + math.pi) % (2 * math.pi) - math.pi
    return math.hypot(dx, dy), abs(dth)


def top_down(
    camera: viser.CameraHandle, centre: tuple[float, float], size: tuple[float, float]
) -> None:
    """Look straight down on a `size` = (width, height) [m] area around `centre`, x right and
    y up on the screen, the whole area in view."""
    half = 0.55 * max(size[0], size[1], 1.0)
    height = half / math.tan(TOP_DOWN_FOV / 2)
    camera.fov = TOP_DOWN_FOV
    camera.far = max(1000.0, 4 * height)
    camera.position = (centre[0], centre[1] - TILT * height, height)
    camera.look_at = (centre[0], centre[1], 0.0)


def follow(camera: viser.CameraHandle, x: float, y: float) -> None:
    """Move the camera sideways (keeping its height and angle) so it looks at (x, y)."""
    look = np.asarray(camera.look_at, dtype=float)
    shift = np.array([x - look[0], y - look[1], 0.0])
    if np.hypot(shift[0], shift[1]) > 1e-3:
        camera.position = np.asarray(camera.position, dtype=float) + shift  # look_at moves too


def metrics_markdown(info: RunInfo | None, p: dict[str, Any], summary: RunSummary | None) -> str:
    """The metrics panel at the timeline's moment: run, simulated time, coverage, what the
    navigation is doing, pose error against the ground truth, real-time factor (live); a note
    (`p["note"]`: looking back, or why a replay has no coverage over time); outcome and B
    errors when done."""
    lines = []
    if info is not None:
        lines.append(f"**Run #{info.id}** · {info.world} · seed {info.seed} · {info.slam}")
    row = []
    if p.get("t") is not None:
        row.append(f"sim time **{p['t']:.1f} s**")
    if p.get("coverage") is not None:
        row.append(f"coverage **{100 * p['coverage']:.1f} %**")
    if p.get("rtf"):
        row.append(f"RTF **{p['rtf']:.1f}x**")
    if p.get("status"):
        row.append(f"{p['status']}, {p.get('goals_reached', 0)} goals")
    lines.append(" · ".join(row))
    if p.get("pose_gt") is not None and p.get("pose_est") is not None:
        et, er = pose_error(p["pose_gt"], p["pose_est"])
        lines.append(f"pose error now: **{et:.3f} m**, **{math.degrees(er):.1f}°** (unaligned)")
    if p.get("note"):
        lines.append(p["note"])
    if p.get("realtime"):  # live: the counters so far
        lines.append(realtime_line(p["realtime"]))
    elif summary is not None and summary.realtime is not None:  # replay: the run's totals
        lines.append(realtime_line(summary.realtime.model_dump()) + " (whole run)")
    if summary:
        lines.append(f"outcome **{summary.outcome}** ({summary.stop})")
        b = summary.relation("B")
        if b is not None:
            tr, rot = b.translation, b.rotation
            lines.append(
                f"B error: trans **{tr.mean:.3f} ± {tr.std:.3f} m**, "
                f"rot **{rot.mean:.4f} ± {rot.std:.4f} rad** ({tr.n} relations)"
            )
    return "\n\n".join(lines)


def realtime_line(rt: dict[str, Any]) -> str:
    """One line on what a real-time SLAM (worker.slam.realtime) kept up with: its computer's
    speed factor (or fixed latency), updates made, scans dropped of those the laser gave, and
    the update latency's mean and maximum."""
    fixed = rt.get("fixed_latency_s")
    mode = f"latency fixed at {fixed:g} s" if fixed is not None else f"computer x{rt['speed']:g}"
    share = rt["scans_dropped"] / rt["scans"] if rt["scans"] else 0.0
    return (
        f"real-time SLAM ({mode}): **{rt['updates']:,}** updates, "
        f"**{rt['scans_dropped']:,}** of {rt['scans']:,} scans dropped ({100 * share:.0f} %), "
        f"latency {rt['latency_mean_s']:.3f} s mean, {rt['latency_max_s']:.3f} s max"
    )


def replay_figures(fin: FinishedRun, t: float) -> dict[str, Any]:
    """A replay's figures at simulated time `t` from the run's stored timeline (a
    `frontend.live.FinishedRun`'s): coverage, status and goals of the last progress report by
    then; without a stored timeline a note says so, beside the final coverage."""
    if fin.timeline is None:
        note = f"coverage over time: {fin.timeline_note}"
        if fin.summary is not None:
            note += f"; at the end **{100 * fin.summary.coverage:.1f} %**"
        return {"note": note}
    now = fin.timeline.at(t)
    if now is None:
        return {"note": f"coverage: first estimate at {fin.timeline.t[0]:.1f} s"}
    return {k: now[k] for k in ("coverage", "status", "goals_reached")}
