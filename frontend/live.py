"""What the viewer shows of one run: live state fed by the worker's messages, or a finished
run read from the database."""

from __future__ import annotations

import bisect
import threading
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from sqlalchemy import select

from backend.db.models import Run, World
from backend.db.session import session_scope
from backend.store import load_map, load_trajectory, world_occupancy
from worker.live_wire import decode_map_patch, ros_codes
from worker.report.summary import RunSummary
from worker.report.timeline import TIMELINE, Timeline
from worker.status import RunOutcome, RunStatus


@dataclass
class RunInfo:
    """A run as the metrics panel names it."""

    id: int
    status: RunStatus
    world_id: int
    world: str
    seed: int
    slam: str
    outcome: RunOutcome | None


def run_info(url: str, run_id: int) -> RunInfo | None:
    """What the metrics panel says of the run (world, seed, SLAM), or None when it is gone."""
    stmt = (
        select(Run.id, Run.status, Run.world_id, World.name, Run.seed, Run.slam, Run.outcome)
        .join(World, World.id == Run.world_id)
        .where(Run.id == run_id)
    )
    with session_scope(url) as s:
        row = s.execute(stmt).first()
    return None if row is None else RunInfo(*row)


def run_status(url: str, run_id: int) -> RunStatus | None:
    """The run's status now, or None when it does not exist."""
    with session_scope(url) as s:
        return s.scalar(select(Run.status).where(Run.id == run_id))


@dataclass
class Floorplan:
    """A world's occupancy grid and where it lies."""

    occ: np.ndarray  # (H, W) bool [iy, ix], bottom row first
    resolution: float  # [m]
    origin: tuple[float, float]  # [m]
    name: str


def load_floorplan(url: str, run_id: int) -> Floorplan | None:
    """The floorplan of the run's world."""
    with session_scope(url) as s:
        run = s.get(Run, run_id)
        if run is None:
            return None
        w = s.get_one(World, run.world_id)
        return Floorplan(world_occupancy(w), w.resolution, (w.origin_x, w.origin_y), w.name)


@dataclass
class MapState:
    """A SLAM map as cell codes (worker.live_wire UNKNOWN / FREE / OCCUPIED)."""

    codes: np.ndarray  # (H, W) uint8 [iy, ix]
    resolution: float  # [m]
    origin: tuple[float, float]  # [m]


@dataclass
class FinishedRun:
    """A finished run from the database: 10 Hz trajectories, final map and summary."""

    t: np.ndarray  # (N,) [s]
    gt: np.ndarray  # (N, 3)
    est: np.ndarray  # (N, 3)
    map: MapState | None
    summary: RunSummary | None
    timeline: Timeline | None = None  # coverage etc. against simulated time
    timeline_note: str = ""  # why there is none

    def index_at(self, t: float) -> int:
        """Index of the last pose at or before `t` (0 before the start)."""
        return max(0, int(np.searchsorted(self.t, t, side="right")) - 1)


def load_finished(url: str, run_id: int) -> FinishedRun | None:
    """A done run's trajectories, map and summary; None when it is not done."""
    with session_scope(url) as s:
        run = s.get(Run, run_id)
        if run is None or run.status != RunStatus.DONE:
            return None
        t, gt = load_trajectory(s, run_id, "gt")
        _, est = load_trajectory(s, run_id, "est")
        try:
            grid, res, origin = load_map(s, run_id)
            state = MapState(ros_codes(grid), res, origin)
        except LookupError:
            state = None
        report_dir = run.report_dir
        fin = FinishedRun(t, gt, est, state, RunSummary.load(run.summary))
    fin.timeline, fin.timeline_note = load_timeline(report_dir)
    return fin


def load_timeline(report_dir: str | None) -> tuple[Timeline | None, str]:
    """The run's timeline.csv read through the storage layer, or None and why not (a run
    from before it was stored, or storage that cannot be reached now)."""
    from worker.storage import StorageError, run_files

    if not report_dir:
        return None, "this run has no report folder"
    try:
        files = run_files(report_dir)
        if files.size(TIMELINE) is None:
            return None, "not stored for this run (it predates the stored series)"
        return Timeline.from_csv(files.read_bytes(TIMELINE).decode("utf-8")), ""
    except (StorageError, OSError, ValueError, UnicodeDecodeError) as exc:
        return None, f"could not be read ({type(exc).__name__})"


@dataclass
class Delta:
    """What one message changed, for the scenes that show the run."""

    progress: dict[str, Any]
    path_reset: bool = False
    gt: np.ndarray | None = None  # (K, 2) new points (all of them after a reset)
    est: np.ndarray | None = None
    scan: np.ndarray | None = None  # (K, 2)
    goal: np.ndarray | None = None  # (2,)
    plan: np.ndarray | None = None  # (K, 2)
    has_nav: bool = False  # goal and plan were in the message (None = there is none)
    map_box: tuple[int, int, int, int] | None = None  # changed (iy0, ix0, h, w)
    map_reset: bool = False  # the map was replaced whole (new size or origin)


@dataclass
class LiveRun:
    """The state of a running run as its messages built it."""

    run_id: int
    gt: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    est: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    map: MapState | None = None
    progress: dict[str, Any] = field(default_factory=dict)
    scan: np.ndarray | None = None
    goal: np.ndarray | None = None
    plan: np.ndarray | None = None
    lock: threading.Lock = field(default_factory=threading.Lock)
    # the timeline's past as it arrived: simulated times, path lengths then, progress then
    hist_t: list[float] = field(default_factory=list)
    hist_n: list[int] = field(default_factory=list)
    hist_p: list[dict[str, Any]] = field(default_factory=list)
    max_history: int = 10000  # moments kept (11 MB measured); beyond, thinned by half
    _every: int = 1  # keep every _every-th moment
    _seen: int = 0

    def apply(self, msg: dict[str, Any]) -> Delta:
        """Fold one message in; the returned Delta says what changed."""
        with self.lock:
            self.progress = msg.get("progress", self.progress)
            d = Delta(self.progress)
            path = msg.get("path")
            if path is not None:
                self._apply_path(path, d)
            if "scan" in msg:
                self.scan = d.scan = np.asarray(msg["scan"], dtype=float).reshape(-1, 2)
            if "goal" in msg:
                d.has_nav = True
                self.goal = d.goal = None if msg["goal"] is None else np.asarray(msg["goal"])
                plan = msg.get("plan")
                self.plan = d.plan = None if plan is None else np.asarray(plan).reshape(-1, 2)
            if "map" in msg:
                self._apply_map(msg["map"], d)
            t = self.progress.get("t")
            if t is not None and (not self.hist_t or t > self.hist_t[-1]):
                self._keep(float(t))
            return d

    def _keep(self, t: float) -> None:
        """Remember this moment; a long watch keeps every other one, evenly."""
        self._seen += 1
        if (self._seen - 1) % self._every:
            return
        if len(self.hist_t) >= self.max_history:  # the 1st, 3rd, ... kept: still evenly spaced
            del self.hist_t[1::2], self.hist_n[1::2], self.hist_p[1::2]
            self._every *= 2
        self.hist_t.append(t)
        self.hist_n.append(len(self.gt))
        self.hist_p.append(self.progress)

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, dict[str, Any] | None]:
        """The paths as they were at simulated time `t` and the progress last reported by
        then (None: before this viewer's first message; the paths sent whole on joining go
        back further, one point per progress report, so their length is interpolated)."""
        with self.lock:
            ts, ns = [0.0, *self.hist_t], [0, *self.hist_n]
            now = self.progress.get("t")
            if now is not None and now > ts[-1]:  # the live edge, past the last moment kept
                ts.append(float(now))
                ns.append(len(self.gt))
            i = bisect.bisect_right(ts, t + 1e-9) - 1
            p = None if i < 1 else self.progress if i > len(self.hist_p) else self.hist_p[i - 1]
            n = ns[i]
            if i + 1 < len(ts):  # between two messages: the points in between by time
                n += int((t - ts[i]) / (ts[i + 1] - ts[i]) * (ns[i + 1] - ns[i]))
            n = max(1, min(n, len(self.gt)))
            return self.gt[:n].copy(), self.est[:n].copy(), p

    def _apply_path(self, path: dict[str, Any], d: Delta) -> None:
        i0 = int(path["i0"])
        gt = np.asarray(path["gt"], dtype=float).reshape(-1, 2)
        est = np.asarray(path["est"], dtype=float).reshape(-1, 2)
        if i0 == 0:
            self.gt, self.est, d.path_reset = gt, est, True
        elif i0 == len(self.gt):
            self.gt, self.est = np.vstack((self.gt, gt)), np.vstack((self.est, est))
        else:
            return  # a gap (we came in between messages): the next message starts over
        d.gt, d.est = gt, est

    def _apply_map(self, m: dict[str, Any], d: Delta) -> None:
        box, patch = decode_map_patch(m)
        shape = tuple(m["shape"])
        origin = (float(m["origin"][0]), float(m["origin"][1]))
        if m["full"] or self.map is None or self.map.codes.shape != shape:
            if not m["full"]:
                return  # a patch of a map we never had whole: wait for the next full one
            self.map = MapState(np.zeros(shape, np.uint8), float(m["resolution"]), origin)
            d.map_reset = True
        iy0, ix0, h, w = box
        self.map.codes[iy0 : iy0 + h, ix0 : ix0 + w] = patch
        d.map_box = box

    def snapshot(self) -> tuple[np.ndarray, np.ndarray, MapState | None]:
        """Copies of the paths and map, for a scene that starts showing the run."""
        with self.lock:
            m = None
            if self.map is not None:
                m = MapState(self.map.codes.copy(), self.map.resolution, self.map.origin)
            return self.gt.copy(), self.est.copy(), m
