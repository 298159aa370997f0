"""The live viewer: one long-lived viser server; running runs arrive over Redis pub/sub,
finished ones come from the database. `mapqual viewer` starts it.

Open `http://HOST:PORT/` and choose a run, or open a run directly with
`http://HOST:PORT/?websocket=ws://HOST:PORT/run/<id>` (the link the dashboard gives): viser's
page connects its websocket to that path, and the path names the run.
"""

from __future__ import annotations

import json
import logging
import queue
import re
import threading
import time
from typing import Any

from frontend.live import (
    LiveRun,
    RunInfo,
    list_runs,
    load_finished,
    load_floorplan,
    run_status,
)
from frontend.view import RunView

log = logging.getLogger("mapqual.viewer")
_RUN_PATH = re.compile(r"^/run/(\d+)/?$")
TICK_S = 0.1  # [s] replay step
POLL_S = 2.0  # [s] run list and status refresh


def run_link(viewer_url: str, run_id: int) -> str:
    """The URL that opens the viewer on one run."""
    base = viewer_url.rstrip("/")
    ws = "wss://" + base[8:] if base.startswith("https://") else "ws://" + base.split("://")[-1]
    return f"{base}/?websocket={ws}/run/{run_id}"


class ViewerApp:
    """The viewer server: per-client views, one Redis listener, one housekeeping thread."""

    def __init__(self, database_url: str, redis_url: str | None, host: str, port: int):
        import viser

        self.url = database_url
        self.server = viser.ViserServer(host=host, port=port, label="mapqual", verbose=False)
        self.server.scene.set_up_direction("+z")
        self.port = self.server.get_port()
        self.views: dict[int, RunView] = {}
        self.live: dict[int, LiveRun] = {}
        self.runs: dict[int, RunInfo] = {}
        self._lock = threading.RLock()
        self._subs: queue.Queue[tuple[str, int]] = queue.Queue()
        self._stop = threading.Event()
        self._redis = _redis(redis_url) if redis_url else None
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)
        self._threads = [
            threading.Thread(target=self._housekeeping, name="viewer-poll", daemon=True),
            threading.Thread(target=self._listen, name="viewer-redis", daemon=True),
        ]
        self._refresh_runs()
        for th in self._threads:
            th.start()

    # --- clients --------------------------------------------------------------------------
    def _connect(self, client: Any) -> None:
        view = RunView(self, client)
        with self._lock:
            self.views[client.client_id] = view
            runs = list(self.runs.values())
        view.set_runs(runs)
        wanted = self._requested_run(client)
        if wanted is not None:
            self.show(view, wanted)

    def _requested_run(self, client: Any) -> int | None:
        """The run named by the websocket path (`/run/<id>`), if any."""
        # viser 1.1.1 keeps each client's websocket connection here; its request has the path
        conns = getattr(getattr(self.server, "_websock_server", None), "_live_connections", {})
        conn = conns.get(client.client_id)
        path = getattr(getattr(conn, "request", None), "path", "") or ""
        m = _RUN_PATH.match(path.partition("?")[0])
        return int(m.group(1)) if m else None

    def _disconnect(self, client: Any) -> None:
        with self._lock:
            view = self.views.pop(client.client_id, None)
            if view is not None and view.run_id is not None:
                self._unwatch(view.run_id)

    def info(self, run_id: int | None) -> RunInfo | None:
        return self.runs.get(run_id) if run_id is not None else None

    def show(self, view: RunView, run_id: int) -> None:
        """Point `view` at `run_id`: live when it is running, a replay when it is done."""
        old = view.run_id
        view.reset(run_id, load_floorplan(self.url, run_id))
        with self._lock:
            if old is not None and old != run_id:
                self._unwatch(old)
        status = run_status(self.url, run_id)
        if status == "done":
            fin = load_finished(self.url, run_id)
            if fin is not None:
                view.show_finished(fin)
        elif status == "running":
            with self._lock:
                live = self.live.get(run_id)
                if live is None:
                    live = self.live[run_id] = LiveRun(run_id)
                    self._subs.put(("subscribe", run_id))
            view.show_live(live)
        if run_id not in self.runs:
            self._refresh_runs()
        view.set_runs(list(self.runs.values()))

    def _unwatch(self, run_id: int) -> None:
        if not any(v.run_id == run_id for v in self.views.values()) and run_id in self.live:
            del self.live[run_id]
            self._subs.put(("unsubscribe", run_id))

    # --- feeds ----------------------------------------------------------------------------
    def _listen(self) -> None:
        """Redis pub/sub: subscribed only to runs somebody watches (the worker sends the heavy
        parts only while somebody listens)."""
        if self._redis is None:
            return
        pubsub = self._redis.pubsub(ignore_subscribe_messages=True)
        while not self._stop.is_set():
            try:
                while not self._subs.empty():
                    op, run_id = self._subs.get_nowait()
                    getattr(pubsub, op)(f"mapqual:run:{run_id}")
                msg = pubsub.get_message(timeout=0.1) if pubsub.subscribed else None
                if msg is None:
                    if not pubsub.subscribed:
                        time.sleep(0.1)
                    continue
                self._on_message(msg)
            except Exception:
                log.exception("viewer: Redis feed failed; reconnecting")
                time.sleep(1.0)
                pubsub = self._resubscribe()

    def _resubscribe(self):
        pubsub = self._redis.pubsub(ignore_subscribe_messages=True)
        with self._lock:
            for run_id in self.live:
                self._subs.put(("subscribe", run_id))
        return pubsub

    def _on_message(self, msg: dict) -> None:
        run_id = int(str(msg["channel"], "utf-8").rsplit(":", 1)[1])
        with self._lock:
            live = self.live.get(run_id)
            views = [v for v in self.views.values() if v.run_id == run_id]
        if live is None:
            return
        delta = live.apply(json.loads(msg["data"]))
        for view in views:
            view.on_delta(live, delta)

    def _housekeeping(self) -> None:
        """Replay ticks; every POLL_S the run list, and finished live runs turn into replays."""
        next_poll = time.monotonic() + POLL_S
        while not self._stop.wait(TICK_S):
            with self._lock:
                views = list(self.views.values())
            for view in views:
                view.tick(TICK_S)
            if time.monotonic() >= next_poll:
                next_poll = time.monotonic() + POLL_S
                try:
                    self._poll(views)
                except Exception:
                    log.exception("viewer: database poll failed")

    def _poll(self, views: list[RunView]) -> None:
        self._refresh_runs()
        runs = list(self.runs.values())
        for view in views:
            view.set_runs(runs)
        with self._lock:
            live_ids = list(self.live)
        for run_id in live_ids:
            if run_status(self.url, run_id) != "running":
                with self._lock:
                    self.live.pop(run_id, None)
                    self._subs.put(("unsubscribe", run_id))
                for view in [v for v in views if v.run_id == run_id and v.mode == "live"]:
                    self.show(view, run_id)  # done: the replay from the database
        for view in [v for v in views if v.mode == "none" and v.run_id is not None]:
            if run_status(self.url, view.run_id) in ("running", "done"):
                self.show(view, view.run_id)  # a queued run has started (or finished)

    def _refresh_runs(self) -> None:
        self.runs = {r.id: r for r in list_runs(self.url)}

    def stop(self) -> None:
        self._stop.set()
        for th in self._threads:
            th.join(timeout=2.0)
        self.server.stop()


def _redis(url: str):
    import redis

    client = redis.Redis.from_url(url, socket_connect_timeout=2, health_check_interval=30)
    try:
        client.ping()
    except Exception:
        log.warning("viewer: no Redis at %s; running runs show once they are done", url)
        return None
    return client
