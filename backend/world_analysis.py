"""Uploaded worlds analysed off the request thread: a bounded pool of spawned processes per
API process turns a `pending` world into `ready` (geometry stored) or `invalid` (reason).

The pool's processes are spawned, not forked, so the API process never imports what the
analysis needs (the loader's numeric stack) and no lock or connection is inherited. Each
process writes its result itself, by a compare-and-set on `status = pending`, so a world
analysed twice (a restart recovering it while another process still works) keeps one result.
"""

from __future__ import annotations

import concurrent.futures as cf
import io
import logging
import multiprocessing as mp
import tempfile
import threading
import zipfile
from pathlib import Path
from typing import Any

from worker.status import WorldStatus

log = logging.getLogger("mapqual.worlds")

CRASHED = (
    "the analysis of this world stopped unexpectedly (its process died, e.g. out of memory); "
    "upload it again to retry"
)


def pack_upload(files: dict[str, bytes]) -> bytes:
    """The uploaded files (name -> bytes) in one blob (a stored, uncompressed zip)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name in sorted(files):
            zf.writestr(name, files[name])
    return buf.getvalue()


def unpack_upload(blob: bytes, folder: Path) -> None:
    """Write the files of `pack_upload`'s blob into `folder` (names are plain file names)."""
    with zipfile.ZipFile(io.BytesIO(blob)) as zf:
        for name in zf.namelist():
            (folder / Path(name).name).write_bytes(zf.read(name))


def without_folder(message: str, folder: Path) -> str:
    """A loader message naming the uploaded files, not the server's temporary folder (the
    folder itself, e.g. from `image: .`, shown as `.`)."""
    from backend.sandbox import scrub_paths

    return scrub_paths(message, folder)


def analyse_world(database_url: str, world_id: int, max_pixels: int) -> WorldStatus | None:
    """In a pool process: load the pending world's upload as `load_world` does and store the
    outcome; returns the world's status afterwards (None: nothing was left to do)."""
    from backend.db.session import session_scope
    from backend.store import mark_world_invalid, mark_world_ready, world_upload
    from worker.errors import InputError
    from worker.world.loader import load_world

    with session_scope(database_url) as s:
        found = world_upload(s, world_id)
    if found is None:
        return None  # finished meanwhile (or deleted): nothing to do
    blob, resolution, main = found
    world, error = None, None
    with tempfile.TemporaryDirectory(prefix="mapqual-world-") as tmp:
        folder = Path(tmp)
        try:
            unpack_upload(blob, folder)
            world = load_world(folder / main, resolution, max_pixels=max_pixels)
        except InputError as exc:
            error = without_folder(str(exc), folder)
        except Exception as exc:  # a loader bug must not leave the world pending forever
            log.exception("analysis of world %s failed", world_id)
            error = f"the floorplan could not be analysed ({exc.__class__.__name__})"
    with session_scope(database_url) as s:
        if world is not None:
            mark_world_ready(s, world_id, world)
            return WorldStatus.READY
        mark_world_invalid(s, world_id, error or "the floorplan could not be analysed")
        return WorldStatus.INVALID


class WorldPool:
    """`workers` spawned processes that analyse worlds; a pool broken by a dying process is
    replaced, and the worlds it held are marked invalid (they can be uploaded again)."""

    def __init__(self, database_url: str, workers: int, max_pixels: int):
        self.database_url = database_url
        self.workers = workers
        self.max_pixels = max_pixels
        self._lock = threading.Lock()
        self._executor: cf.ProcessPoolExecutor | None = None
        self._futures: dict[int, cf.Future[WorldStatus | None]] = {}

    def submit(self, world_id: int) -> cf.Future[WorldStatus | None]:
        """The analysis of `world_id` (the one already under way, if any)."""
        with self._lock:
            running = self._futures.get(world_id)
            if running is not None and not running.done():
                return running
            if self._executor is None:
                self._executor = cf.ProcessPoolExecutor(
                    self.workers, mp_context=mp.get_context("spawn")
                )
            future = self._executor.submit(
                analyse_world, self.database_url, world_id, self.max_pixels
            )
            self._futures[world_id] = future
        future.add_done_callback(lambda f: self._done(world_id, f))
        return future

    def running(self, world_id: int) -> cf.Future[WorldStatus | None] | None:
        """The analysis of `world_id` in this process, if one was started and is not done."""
        with self._lock:
            future = self._futures.get(world_id)
        return None if future is None or future.done() else future

    def _done(self, world_id: int, future: cf.Future[WorldStatus | None]) -> None:
        with self._lock:
            if self._futures.get(world_id) is future:
                del self._futures[world_id]
        if future.cancelled():
            return  # shutting down: the world stays pending, the next start redoes it
        exc = future.exception()
        if exc is None:
            return
        log.error("analysis of world %s failed: %r", world_id, exc)
        if isinstance(exc, cf.process.BrokenProcessPool):
            with self._lock:
                self._executor = None  # the next submit starts a fresh pool
        self._mark_invalid(world_id)

    def _mark_invalid(self, world_id: int) -> None:
        from backend.db.session import session_scope
        from backend.store import mark_world_invalid

        try:
            with session_scope(self.database_url) as s:
                mark_world_invalid(s, world_id, CRASHED)
        except Exception:  # the database is gone too: the world stays pending for recovery
            log.exception("could not mark world %s invalid", world_id)

    def shutdown(self) -> None:
        """Stop the processes; queued analyses are dropped (their worlds stay pending)."""
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)


def world_pool(app: Any) -> WorldPool:
    """The app's pool (made on first use, with the app's settings)."""
    pool = getattr(app.state, "world_pool", None)
    if pool is None:
        settings = app.state.settings
        pool = app.state.world_pool = WorldPool(
            settings.database_url, settings.world_workers, settings.max_image_pixels
        )
    return pool


def recover_pending(app: Any) -> list[int]:
    """Hand every world left `pending` (by a process that died) to the pool again."""
    from backend.db.session import session_scope
    from backend.store import pending_world_ids

    with session_scope(app.state.settings.database_url) as s:
        ids = pending_world_ids(s)
    pool = world_pool(app)
    for world_id in ids:
        pool.submit(world_id)
    return ids
