"""One browser tab of the viewer: its GUI (metrics, layers, replay) and its scene, showing the
one run its link names, live or replayed once finished; or, without a valid link, a note."""

from __future__ import annotations

import contextlib
import math
import threading
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from frontend.layers import EST_RGB, GT_RGB, Floorplan, MapTiles, Markers, PathLayer, Robot
from frontend.live import Delta, FinishedRun, LiveRun, RunInfo
from frontend.panel import (
    follow,
    legend_html,
    metrics_markdown,
    run_title,
    title_html,
    top_down,
)

if TYPE_CHECKING:
    from frontend.viewer import ViewerApp

NEED_LINK = (
    "**No run to show.** This viewer opens a run only through the *open viewer* link on the "
    "run's job page in the dashboard (signed in as its owner)."
)
EXPIRED = "**This viewer link has expired.** Open the run again from its job page in the dashboard."
ENDED = "**This run is no longer shown:** your access to it has ended."
UNAVAILABLE = "**The viewer cannot check this link just now.** Reload the page in a moment."
Note = Literal["link", "expired", "unavailable"]
NOTES: dict[Note, str] = {"link": NEED_LINK, "expired": EXPIRED, "unavailable": UNAVAILABLE}
SPEEDS = ("1x", "2x", "5x", "10x", "20x", "50x", "100x")
REPLAY_POINTS = 20000  # finished paths are drawn with at most this many points
LAYERS = ("floorplan", "SLAM map", "ground truth", "estimate", "robots", "scan", "goal & plan")


class RunView:
    """The GUI and scene of one connected client."""

    def __init__(self, app: ViewerApp, client: Any, user_id: int):
        self.app, self.client, self.scene = app, client, client.scene
        self.user_id = user_id  # whom the link was made for (access is checked again as it runs)
        self.lock = threading.RLock()
        self.run_id: int | None = None
        self.info: RunInfo | None = None
        self.mode = "none"  # none | live | replay | closed
        self.finished: FinishedRun | None = None
        self.stride = 1
        self.shown_i = -1  # replay: last trajectory index drawn
        self.playing = False
        self._build_gui(client.gui)
        self._layers: dict[str, Any] = {}

    # --- GUI ------------------------------------------------------------------------------
    def _build_gui(self, gui: Any) -> None:
        # no run chooser: a link opens one run, and that is all this client may see
        self.title = gui.add_html(title_html(run_title(None)))
        self._folders = [gui.add_folder("Metrics")]
        with self._folders[-1]:
            self.metrics = gui.add_markdown("Loading the run...")
        self._folders.append(gui.add_folder("Timeline"))
        with self._folders[-1]:
            self.play = gui.add_button("Play", disabled=True)
            self.speed = gui.add_dropdown("speed", SPEEDS, initial_value="10x")
            self.slider = gui.add_slider("time [s]", 0.0, 1.0, 0.1, 0.0, disabled=True)
        self.play.on_click(lambda _: self._toggle_play())
        self.slider.on_update(lambda _: self._on_slider())
        self._folders.append(gui.add_folder("View"))
        with self._folders[-1]:
            self.follow = gui.add_checkbox("follow robot", False)
            self.top_down = gui.add_button("top-down view of the whole world")
        self.top_down.on_click(lambda _: self._reframe())
        self._folders.append(gui.add_folder("Layers"))
        with self._folders[-1]:
            self.toggles = {name: gui.add_checkbox(name, True) for name in LAYERS}
        for name, box in self.toggles.items():
            box.on_update(lambda _, n=name: self._apply_toggle(n))
        self._folders.append(gui.add_folder("Legend", expand_by_default=True))
        with self._folders[-1]:
            gui.add_html(legend_html())

    def close(self) -> None:
        """Access ended while watching: the scene and the panel are emptied, a note says why."""
        with self.lock:
            self._clear()
            self.scene.reset()  # the layers' parent frames too: this client's scene only
            self.mode, self.finished, self.playing = "closed", None, False
            for folder in self._folders:
                folder.remove()
            self._folders = []
            self.client.gui.add_markdown(ENDED)

    def _apply_toggle(self, name: str) -> None:
        on = self.toggles[name].value
        with self.lock:
            L = self._layers
            if not L:
                return
            if name == "floorplan" and L.get("floor") is not None:
                L["floor"].node.visible = on
                L["map"].set_floor(L["floor"], on)
            elif name == "SLAM map":
                L["map"].set_visible(on)
            elif name == "ground truth":
                L["gt"].set_visible(on)
            elif name == "estimate":
                L["est"].set_visible(on)
            elif name == "robots":
                L["robot_gt"].set_visible(on)
                L["robot_est"].set_visible(on)
            elif name == "scan":
                L["markers"].set_scan_visible(on)
            else:
                L["markers"].set_nav_visible(on)

    # --- scene ----------------------------------------------------------------------------
    def reset(self, run_id: int, floor) -> None:
        """Clear the scene and lay out the layers for `run_id` over its floorplan."""
        with self.lock:
            if self.mode == "closed":
                return
            self._clear()
            reframe = run_id != self.run_id  # the same run again (it finished): keep the camera
            self.run_id, self.mode, self.finished, self.playing = run_id, "none", None, False
            on = {n: b.value for n, b in self.toggles.items()}
            sc = self.scene
            L: dict[str, Any] = {"floor": None}
            if floor is not None:
                L["floor"] = Floorplan(sc, "/floor", floor.occ, floor.resolution, floor.origin)
                L["floor"].node.visible = on["floorplan"]
                if reframe:
                    top_down(self.client.camera, L["floor"].centre, L["floor"].size)
            L["map"] = MapTiles(sc, "/slam", on["SLAM map"])
            L["map"].floor, L["map"].floor_on = L["floor"], on["floorplan"]
            L["gt"] = PathLayer(sc, "/gt", GT_RGB, 0.08, on["ground truth"])
            L["est"] = PathLayer(sc, "/est", EST_RGB, 0.05, on["estimate"])
            L["robot_gt"] = Robot(sc, "/robot_gt", GT_RGB, visible=on["robots"])
            L["robot_est"] = Robot(sc, "/robot_est", EST_RGB, 0.35, visible=on["robots"])
            L["markers"] = Markers(sc, "/nav", on["scan"], on["goal & plan"])
            self._layers = L
            self._sync_replay_gui()
            self.title.content = title_html(run_title(self.info))
            self.metrics.content = metrics_markdown(self.info, {}, None)

    def _clear(self) -> None:
        L = self._layers
        if L:
            if L.get("floor") is not None:
                L["floor"].node.remove()
            L["map"].clear()
            L["gt"].clear()
            L["est"].clear()
            for k in ("robot_gt", "robot_est"):
                L[k].node.remove()
            m = L["markers"]
            m.scan.remove()
            m.goal.remove()
            if m.plan is not None:
                m.plan.remove()
        self._layers = {}

    def _reframe(self) -> None:
        """The top-down view of the whole floorplan (follow-robot is switched off)."""
        with self.lock:
            floor = self._layers.get("floor")
            if floor is not None:
                self.follow.value = False
                top_down(self.client.camera, floor.centre, floor.size)

    def show_live(self, live: LiveRun) -> None:
        """Start showing a running run from what has arrived so far."""
        gt, est, m = live.snapshot()
        with self.lock:
            if self.mode == "closed":
                return
            self.mode = "live"
            L = self._layers
            L["gt"].set(gt)
            L["est"].set(est)
            if m is not None:
                L["map"].show(m.codes, m.resolution, m.origin)
            self._progress(live.progress)
            self._sync_replay_gui()

    def on_delta(self, live: LiveRun, d: Delta) -> None:
        """A message of the run we show arrived."""
        with self.lock:
            if self.mode != "live":
                return
            L = self._layers
            if d.gt is not None:
                (L["gt"].set if d.path_reset else L["gt"].append)(d.gt)
                (L["est"].set if d.path_reset else L["est"].append)(d.est)
            if d.map_box is not None and live.map is not None:
                box = None if d.map_reset else d.map_box
                L["map"].show(live.map.codes, live.map.resolution, live.map.origin, box)
            if d.scan is not None:
                L["markers"].show_scan(d.scan)
            if d.has_nav:
                L["markers"].show_nav(d.goal, d.plan)
            self._progress(d.progress)

    def _progress(self, p: dict[str, Any]) -> None:
        L = self._layers
        if "pose_gt" in p:
            L["robot_gt"].pose(*p["pose_gt"])
            L["robot_est"].pose(*p["pose_est"])
            self._follow(p["pose_gt"])
        if p.get("t") is not None:  # the timeline's live edge
            t = round(float(p["t"]), 1)
            self.slider.max = max(t, 0.1)
            self.slider.value = t
        self.metrics.content = metrics_markdown(self.info, p, None)

    def _follow(self, pose) -> None:
        if self.follow.value:
            # until the browser has told its camera, there is none to move: the next pose will
            with contextlib.suppress(AssertionError, ValueError):
                follow(self.client.camera, float(pose[0]), float(pose[1]))

    # --- replay ---------------------------------------------------------------------------
    def show_finished(self, fin: FinishedRun) -> None:
        """Show a finished run at its end, ready to replay."""
        with self.lock:
            if self.mode == "closed":
                return
            self.mode, self.finished, self.playing = "replay", fin, False
            self.stride = max(1, math.ceil(len(fin.t) / REPLAY_POINTS))
            L = self._layers
            L["markers"].show_scan(None)
            L["markers"].show_nav(None, None)
            if fin.map is not None:
                L["map"].show(fin.map.codes, fin.map.resolution, fin.map.origin)
            self.shown_i = -1
            end = float(fin.t[-1]) if len(fin.t) else 0.0
            self._sync_replay_gui()
            self.slider.max = max(end, 0.1)
            if self.slider.value == end:
                self._render_at(end)
            else:
                self.slider.value = end  # renders (the slider's callback)

    def _sync_replay_gui(self) -> None:
        """One timeline: it follows the simulated time while the run is live (the live edge,
        not draggable: the past of a live run is not kept here), and plays and seeks once it
        is done."""
        replay = self.mode == "replay"
        self.play.disabled = not replay
        self.slider.disabled = not replay
        if self.mode == "live":
            self.play.label = "Live (replay once done)"
        else:
            self.play.label = "Pause" if self.playing else "Play"

    def _toggle_play(self) -> None:
        with self.lock:
            if self.mode != "replay":
                return
            if not self.playing and self.slider.value >= self.slider.max - 1e-6:
                self.slider.value = 0.0  # play again from the start
            self.playing = not self.playing
            self._sync_replay_gui()

    def _on_slider(self) -> None:
        with self.lock:
            if self.mode == "replay":
                self._render_at(float(self.slider.value))

    def tick(self, dt: float) -> None:
        """Advance a playing replay by `dt` wall seconds at the chosen speed."""
        with self.lock:
            if self.mode != "replay" or not self.playing:
                return
            t = min(self.slider.max, self.slider.value + dt * float(self.speed.value[:-1]))
            if t >= self.slider.max:
                self.playing = False
                self._sync_replay_gui()
            self.slider.value = round(t, 1)  # renders (the slider's callback)

    def _render_at(self, t: float) -> None:
        fin, L = self.finished, self._layers
        if fin is None or not len(fin.t):
            return
        i = fin.index_at(t)
        idx = np.arange(0, i + 1, self.stride)
        if idx[-1] != i:
            idx = np.append(idx, i)
        if i < self.shown_i or self.shown_i < 0:
            L["gt"].set(fin.gt[idx, :2])
            L["est"].set(fin.est[idx, :2])
        elif i > self.shown_i:
            new = idx[idx > self.shown_i]
            L["gt"].append(fin.gt[new, :2])
            L["est"].append(fin.est[new, :2])
        self.shown_i = i
        L["robot_gt"].pose(*fin.gt[i])
        L["robot_est"].pose(*fin.est[i])
        self._follow(fin.gt[i])
        p = {"t": float(fin.t[i]), "pose_gt": fin.gt[i], "pose_est": fin.est[i],
             "final_coverage": fin.summary.coverage if fin.summary else None}  # fmt: skip
        self.metrics.content = metrics_markdown(self.info, p, fin.summary)

    def describe(self) -> dict[str, Any]:
        """What the scene holds now (for tests and the status line)."""
        with self.lock:
            L = self._layers
            if not L:
                return {"run": self.run_id, "mode": self.mode}
            return {
                "run": self.run_id,
                "mode": self.mode,
                "floorplan": L["floor"] is not None,
                "map_tiles": L["map"].n_tiles(),
                "gt_points": len(L["gt"].points),
                "est_points": len(L["est"].points),
                "robot_gt": L["robot_gt"].shown,
                "robot_est": L["robot_est"].shown,
                "scan": L["markers"].has_scan,
                "goal": L["markers"].has_goal,
            }


def refuse(client: Any, note: Note) -> None:
    """A client without a valid link: a note on its panel, and nothing of any run."""
    client.gui.add_markdown(NOTES[note])
