"""The live viewer: one long-lived viser server; running runs arrive over Redis pub/sub,
finished ones come from the database. `mapqual viewer` starts it.

A client sees one run, and only through the link its job's dashboard page gives:
`http://HOST:PORT/?websocket=ws://HOST:PORT/run/<id>/<token>`. viser's page connects its
websocket to that path; the path names the run and carries a signed, expiring token for it
(`backend.core.viewer_tokens`). Without a valid one the client sees a note and nothing else.
"""

from __future__ import annotations

import json
import logging
import queue
import re
import threading
import time
from typing import TYPE_CHECKING

from backend.core.viewer_tokens import InvalidToken, authorise, check_access, signing_key
from backend.db.session import session_scope
from frontend.live import LiveRun, load_finished, load_floorplan, run_info, run_status
from frontend.view import Note, RunView, refuse
from worker.status import RunStatus

if TYPE_CHECKING:
    import viser

log = logging.getLogger("mapqual.viewer")
_RUN_PATH = re.compile(r"^/run/(\d{1,18})/([^/]*)/?$")
TICK_S = 0.1  # [s] replay step
POLL_S = 2.0  # [s] status refresh, and how soon a revoked user's open views go blank


def run_link(viewer_url: str, run_id: int, token: str) -> str:
    """The URL that opens the viewer on one run, with a token for it (`viewer_tokens.issue`)."""
    base = viewer_url.rstrip("/")
    ws = "wss://" + base[8:] if base.startswith("https://") else "ws://" + base.split("://")[-1]
    return f"{base}/?websocket={ws}/run/{run_id}/{token}"


class ViewerApp:
    """The viewer server: per-client views, one Redis listener, one housekeeping thread."""

    def __init__(
        self,
        database_url: str,
        redis_url: str | None,
        host: str,
        port: int,
        secret_key: str | None = None,
    ):
        import viser

        self.url = database_url
        # the key the dashboard signs links with (made in the database on first use)
        self.key = signing_key(database_url, secret_key)
        self.server = viser.ViserServer(host=host, port=port, label="mapqual", verbose=False)
        self.server.scene.set_up_direction("+z")
        # viser's Share button has the server open a public tunnel (share.viser.studio) at any
        # client's request, refused client or not; that would bypass binding the viewer to
        # 127.0.0.1. Hidden, and refused on the server (its handler looks the method up on
        # every request, so the instance attribute wins).
        self.server.gui.configure_theme(show_share_button=False)
        self.server.request_share_url = _no_share_url  # type: ignore[method-assign]
        self.port = self.server.get_port()
        self.views: dict[int, RunView] = {}
        # clients refused (client id -> why), shown a note and nothing else
        self.refused: dict[int, str] = {}
        self.live: dict[int, LiveRun] = {}
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
        for th in self._threads:
            th.start()

    # --- clients --------------------------------------------------------------------------
    def _connect(self, client: viser.ClientHandle) -> None:
        try:
            run_id, user_id = self._authorise(client)
        except InvalidToken as exc:
            log.info("viewer: client %s refused: %s", client.client_id, exc.reason)
            self._refuse(client, exc.reason, "expired" if exc.expired else "link")
            return
        except Exception:  # the database is unreachable: the link cannot be checked now
            log.exception("viewer: could not check client %s's link", client.client_id)
            self._refuse(client, "the link could not be checked", "unavailable")
            return
        view = RunView(client, user_id)
        with self._lock:
            self.views[client.client_id] = view
        self.show(view, run_id)

    def _refuse(self, client: viser.ClientHandle, reason: str, note: Note) -> None:
        with self._lock:
            self.refused[client.client_id] = reason
        refuse(client, note)

    def _authorise(self, client: viser.ClientHandle) -> tuple[int, int]:
        """The run the client's link names and the user it was made for; InvalidToken unless
        the link's token is valid for that run and the user may still see it."""
        # viser 1.1.1 keeps each client's websocket connection here; its request has the path
        conns = getattr(getattr(self.server, "_websock_server", None), "_live_connections", {})
        conn = conns.get(client.client_id)
        path = getattr(getattr(conn, "request", None), "path", "") or ""
        m = _RUN_PATH.match(path.partition("?")[0])
        if m is None:
            raise InvalidToken(f"no run link in the websocket path {path[:80]!r}")
        run_id = int(m.group(1))
        with session_scope(self.url) as s:
            grant = authorise(s, self.key, run_id, m.group(2))
        return run_id, grant.user_id

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            self.refused.pop(client.client_id, None)
            view = self.views.pop(client.client_id, None)
            if view is not None and view.run_id is not None:
                self._unwatch(view.run_id)

    def show(self, view: RunView, run_id: int) -> None:
        """Point `view` at `run_id`: live when it is running, a replay when it is done."""
        old = view.run_id
        if view.info is None or view.info.id != run_id:
            view.info = run_info(self.url, run_id)
        view.reset(run_id, load_floorplan(self.url, run_id))
        if view.mode == "closed":
            return  # access ended meanwhile: subscribe to nothing for it
        with self._lock:
            if old is not None and old != run_id:
                self._unwatch(old)
        status = run_status(self.url, run_id)
        if status == RunStatus.DONE:
            fin = load_finished(self.url, run_id)
            if fin is not None:
                view.show_finished(fin)
        elif status == RunStatus.RUNNING:
            with self._lock:
                live = self.live.get(run_id)
                if live is None:
                    live = self.live[run_id] = LiveRun(run_id)
                    self._subs.put(("subscribe", run_id))
            view.show_live(live)

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
        """Replay ticks; every POLL_S access is checked again, and finished live runs turn into
        replays."""
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
        views = self._recheck(views)
        with self._lock:
            live_ids = list(self.live)
        for run_id in live_ids:
            if run_status(self.url, run_id) != RunStatus.RUNNING:
                with self._lock:
                    self.live.pop(run_id, None)
                    self._subs.put(("unsubscribe", run_id))
                for view in [v for v in views if v.run_id == run_id and v.mode == "live"]:
                    self.show(view, run_id)  # done: the replay from the database
        for view in [v for v in views if v.mode == "none" and v.run_id is not None]:
            if run_status(self.url, view.run_id) in (RunStatus.RUNNING, RunStatus.DONE):
                self.show(view, view.run_id)  # a queued run has started (or finished)

    def _recheck(self, views: list[RunView]) -> list[RunView]:
        """Close the views whose user may no longer see the run (revoked, or the run changed
        owner) and return the others. A token's expiry matters when a page connects only: a
        run watched live may outlast the link that opened it."""
        pairs = {(v.run_id, v.user_id) for v in views if v.run_id is not None}
        if not pairs:
            return views
        denied: set[tuple[int | None, int]] = set()
        with session_scope(self.url) as s:
            for run_id, user_id in pairs:
                try:
                    check_access(s, run_id, user_id)
                except InvalidToken as exc:
                    log.info("viewer: run %s closed for user %s: %s", run_id, user_id, exc.reason)
                    denied.add((run_id, user_id))
        kept = []
        for view in views:
            if (view.run_id, view.user_id) not in denied:
                kept.append(view)
                continue
            view.close()
            with self._lock:
                self.views.pop(view.client.client_id, None)
                self.refused[view.client.client_id] = "access ended while watching"
                self._unwatch(view.run_id)
        return kept

    def stop(self) -> None:
        self._stop.set()
        for th in self._threads:
            th.join(timeout=2.0)
        self.server.stop()


def _no_share_url(verbose: bool = True) -> None:
    log.warning("viewer: a client asked for a public share URL; refused")


def _redis(url: str):
    import redis

    client = redis.Redis.from_url(url, socket_connect_timeout=2, health_check_interval=30)
    try:
        client.ping()
    except Exception:
        log.warning("viewer: no Redis at %s; running runs show once they are done", url)
        return None
    return client
