"""Uploaded worlds analysed off the request thread: `world_workers` threads per API process
turn a `pending` world into `ready` (geometry stored) or `invalid` (reason), each analysis in
a limited process of its own (`backend.sandbox.manager`, kind "analysis": address space, CPU
and wall time from the `analysis_*` settings), forked from a warm process that loaded the analysis
once. The API process never imports what the analysis needs (numba).

The analysis starts from the floorplan the upload sandbox read (`worker.world.floorplan`),
never from the raw upload; a small plan's was made where it was read (`remember`), sparing
its world a second process. Its outcome is stored by a compare-and-set on `status = pending`,
so a world analysed twice (a restart recovering it while another process still works) keeps
one result.
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import hashlib
import io
import logging
import threading
import zipfile
from collections import OrderedDict
from typing import TYPE_CHECKING, Any

import numpy as np

from backend.sandbox.manager import Sandbox, shared_sandbox
from worker.status import WorldStatus

if TYPE_CHECKING:
    from backend.core.config import Settings

log = logging.getLogger("mapqual.worlds")

CRASHED = "the analysis of this world stopped unexpectedly; upload it again to retry"
PLAN = "floorplan.bin"  # the floorplan's file name in the analysis's folder


def pack_upload(files: dict[str, bytes]) -> bytes:
    """The uploaded files (name -> bytes) in one blob (a stored, uncompressed zip): what a
    pending world held before floorplans were read in the request (still analysed)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name in sorted(files):
            zf.writestr(name, files[name])
    return buf.getvalue()


# Analyses made where small uploads were read (`backend.sandbox.tasks.floorplan`), by the
# floorplan bytes' digest, until their world's analysis takes them; the oldest dropped past
# KNOWN_MAX (a world whose entry is gone is analysed in the analysis sandbox instead).
KNOWN_MAX = 256
_KNOWN: OrderedDict[bytes, dict[str, Any]] = OrderedDict()
_KNOWING = threading.Lock()


def remember(blob: bytes, analysis: object) -> None:
    """Keep the analysis the read of `blob` made (facts, start pose, warnings; or error)."""
    if isinstance(analysis, dict):
        with _KNOWING:
            _KNOWN[hashlib.sha256(blob).digest()] = analysis
            while len(_KNOWN) > KNOWN_MAX:
                _KNOWN.popitem(last=False)


def _recall(blob: bytes) -> dict[str, Any] | None:
    with _KNOWING:
        return _KNOWN.pop(hashlib.sha256(blob).digest(), None)


def analyse_world(box: Sandbox, database_url: str, world_id: int) -> WorldStatus | None:
    """Analyse the pending world's floorplan in `box` and store the outcome; returns the
    world's status afterwards (None: nothing was left to do)."""
    from backend.db.session import session_scope
    from backend.store import mark_world_invalid, mark_world_ready, world_upload
    from worker.errors import InputError

    with session_scope(database_url) as s:
        found = world_upload(s, world_id)
    if found is None:
        return None  # finished meanwhile (or deleted): nothing to do
    blob, resolution, main = found
    world, error = None, None
    try:
        world = _analysed(box, blob, resolution, main)
    except InputError as exc:
        error = str(exc)
    except Exception as exc:  # a bug of ours must not leave the world pending forever
        log.exception("analysis of world %s failed", world_id)
        error = f"the floorplan could not be analysed ({exc.__class__.__name__})"
    with session_scope(database_url) as s:
        if world is not None:
            mark_world_ready(s, world_id, world)
            return WorldStatus.READY
        mark_world_invalid(s, world_id, error or "the floorplan could not be analysed")
        return WorldStatus.INVALID


def _analysed(box: Sandbox, blob: bytes, resolution: float | None, main: str):
    """The World of a stored floorplan, its analysis done in `box`; its facts checked."""
    from worker.errors import InputError
    from worker.world.floorplan import unpack_floorplan
    from worker.world.world import World, WorldFacts

    max_pixels = box.settings.max_image_pixels
    if blob.startswith(b"PK"):  # the raw upload an older server stored: read as uploads are
        blob = _read_stored_upload(box, blob, main, resolution)
    f = _recall(blob)
    if f is None:
        f = box.run("world", {PLAN: blob}, label=main, file=PLAN, max_pixels=max_pixels).facts
    elif "error" in f:  # analysed where it was read, and refused there
        raise InputError(str(f["error"])[:500])
    facts, pose, notes = f.get("facts"), f.get("start_pose"), f.get("warnings")
    names = {x.name for x in dataclasses.fields(WorldFacts)}
    if (
        not isinstance(facts, dict) or set(facts) != names
        or not all(v is None or type(v) in (int, float, bool) for v in facts.values())
        or not isinstance(pose, list) or len(pose) != 3
        or not all(type(v) in (int, float) and np.isfinite(v) for v in pose)
        or not isinstance(notes, list) or not all(isinstance(n, str) for n in notes)
    ):  # fmt: skip
        raise InputError(f"{main}: could not be analysed (a malformed result)")
    plan = unpack_floorplan(blob, max_pixels)
    return World(
        name=plan.name, occ=plan.occ, resolution=plan.resolution,
        origin=np.asarray(plan.origin, float), start_pose=np.asarray(pose, float),
        facts=WorldFacts(**facts), warnings=tuple(notes), source=main,
    )  # fmt: skip


def _read_stored_upload(box: Sandbox, blob: bytes, main: str, resolution: float | None) -> bytes:
    """A floorplan's bytes from `pack_upload`'s zip (stored by this server, its names plain
    file names), read in the upload sandbox."""
    from backend.services.worlds import read_upload

    with zipfile.ZipFile(io.BytesIO(blob)) as zf:
        files = {name: zf.read(name) for name in zf.namelist()}
    return read_upload(box.settings, files, main, resolution)


class WorldPool:
    """`world_workers` threads that analyse worlds, each in the analysis sandbox's limited
    processes; a world whose analysis failed on our side is marked invalid (it can be
    uploaded again)."""

    def __init__(self, settings: Settings):
        self.database_url = settings.database_url
        self.box = shared_sandbox(settings, "analysis")
        self._lock = threading.Lock()
        self._workers = settings.world_workers
        self._executor: cf.ThreadPoolExecutor | None = None
        self._futures: dict[int, cf.Future[WorldStatus | None]] = {}

    def start(self) -> None:
        """Start the analysis processes now (an API's start-up), not at the first upload."""
        self.box.start()

    def submit(self, world_id: int) -> cf.Future[WorldStatus | None]:
        """The analysis of `world_id` (the one already under way, if any)."""
        with self._lock:
            running = self._futures.get(world_id)
            if running is not None and not running.done():
                return running
            if self._executor is None:
                self._executor = cf.ThreadPoolExecutor(
                    self._workers, thread_name_prefix="mapqual-world"
                )
            future = self._executor.submit(analyse_world, self.box, self.database_url, world_id)
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
        """Stop the threads and the idle analysis processes; queued analyses are dropped
        (their worlds stay pending)."""
        with self._lock:
            executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=True, cancel_futures=True)
        self.box.shutdown()
