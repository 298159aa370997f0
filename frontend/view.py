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
    replay_figures,
    run_title,
    title_html,
    top_down,
)

if TYPE_CHECKING:
    import viser

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

    def __init__(self, client: viser.ClientHandle, user_id: int):
        self.client, self.scene = client, client.scene
        self.user_id = user_id  # whom the link was made for (access is checked again as it runs)
        self.lock = threading.RLock()
        self.run_id: int | None = None
        self.info: RunInfo | None = None
        self.mode = "none"  # none | live | replay | closed
        self.finished: FinishedRun | None = None
        self.stride = 1
        self.shown_i = -1  # replay: last trajectory index drawn
        self.playing = False
        self.live: LiveRun | None = None
        self.following = True  # live: the timeline at the live edge (False: looking back)
        self._build_gui(client.gui)
        self._layers: dict[str, Any] = {}

    # --- GUI ------------------------------------------------------------------------------
    def _build_gui(self, gui: viser.GuiApi) -> None:
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
        self.slider.on_update(self._on_slider)
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
            self.live, self.following = None, True
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
            self.mode, self.live, self.following = "live", live, True
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
            if d.map_box is not None and live.map is not None:
                box = None if d.map_reset else d.map_box
                L["map"].show(live.map.codes, live.map.resolution, live.map.origin, box)
            if not self.following:  # looking back: the live edge moves on, the scene stays
                self.slider.max = max(round(float(d.progress.get("t") or 0.0), 1), 0.1)
                self._scrub_live(float(self.slider.value), redraw=False)
                return
            if d.gt is not None:
                (L["gt"].set if d.path_reset else L["gt"].append)(d.gt)
                (L["est"].set if d.path_reset else L["est"].append)(d.est)
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

    def _scrub_live(self, t: float, redraw: bool = True) -> None:
        """Show the live run as it was at `t` while it runs on: paths, robots and figures of
        that moment (`redraw` False: the figures only); the SLAM map stays the latest (its past
        is not kept)."""
        live, L = self.live, self._layers
        edge = float(self.slider.max)
        if live is None or (redraw and t >= edge - 0.05):
            self._go_live()
            return
        self.following = False
        gt, est, p = live.at(t)
        if redraw:
            L["gt"].set(gt)
            L["est"].set(est)
            L["markers"].show_scan(None)
            L["markers"].show_nav(None, None)
        shown = dict(p or {}, t=t)
        if p is not None and redraw:
            L["robot_gt"].pose(*p["pose_gt"])
            L["robot_est"].pose(*p["pose_est"])
        elif p is None:
            shown["note"] = "no figures for this moment: this viewer joined the run later"
        shown["note"] = " · ".join(
            filter(None, [shown.get("note"), f"**looking back**: live is at {edge:.1f} s; "
                          "the SLAM map shown is the latest"])
        )  # fmt: skip
        self.metrics.content = metrics_markdown(self.info, shown, None)
        self._sync_replay_gui()

    def _go_live(self) -> None:
        """Back to the live edge: the paths, scan and plan as they are now."""
        live, L = self.live, self._layers
        if live is None:
            return
        self.following = True
        gt, est, _ = live.snapshot()
        L["gt"].set(gt)
        L["est"].set(est)
        with live.lock:
            scan, goal, plan, progress = live.scan, live.goal, live.plan, dict(live.progress)
        L["markers"].show_scan(scan)
        L["markers"].show_nav(goal, plan)
        self._progress(progress)
        self._sync_replay_gui()

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
        """One timeline: while the run is live it follows the live edge, and dragged back it
        shows the run's past while the run goes on (the button returns to live); once done it
        plays and seeks."""
        replay, live = self.mode == "replay", self.mode == "live"
        self.play.disabled = not replay and not (live and not self.following)
        self.slider.disabled = not (replay or live)
        if live:
            self.play.label = "Live" if self.following else "Back to live"
        else:
            self.play.label = "Pause" if self.playing else "Play"

    def _toggle_play(self) -> None:
        with self.lock:
            if self.mode == "live":
                self._go_live()
                return
            if self.mode != "replay":
                return
            if not self.playing and self.slider.value >= self.slider.max - 1e-6:
                self.slider.value = 0.0  # play again from the start
            self.playing = not self.playing
            self._sync_replay_gui()

    def _on_slider(self, event: viser.GuiEvent) -> None:
        with self.lock:
            if self.mode == "replay":
                self._render_at(float(self.slider.value))
            elif self.mode == "live" and getattr(event, "client", None) is not None:
                t = round(float(self.slider.value), 1)  # a user's move, not the live edge's
                self._scrub_live(t)
                if not self.following:
                    # the live edge's values sent before this move reached us arrive after it
                    # and move the page's slider: send the chosen time once more, last
                    self.slider.value = t + 0.1
                    self.slider.value = t

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
        p = {"t": float(fin.t[i]), "pose_gt": fin.gt[i], "pose_est": fin.est[i]}
        p.update(replay_figures(fin, float(fin.t[i])))
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


def refuse(client: viser.ClientHandle, note: Note) -> None:
    """A client without a valid link: a note on its panel, and nothing of any run."""
    client.gui.add_markdown(NOTES[note])
