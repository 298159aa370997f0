"""The bundled data sets for the service: loaded once per process and again only when their
files change, their thumbnails cached, and a bundled world imported as a world of the caller.

The catalogue is per process, not per app: the files are the process's, and an app per test
(or per `create_app`) would otherwise load the 63 bundled worlds (seconds) each time. The
bundled worlds are trusted files of the checkout, so they are loaded in the API process (an
upload is analysed in the world pool's processes instead)."""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from backend.core.config import Settings
from backend.db.models import World
from backend.services import quotas
from backend.services.access import Principal
from backend.services.errors import NotFound
from backend.store.worlds import save_world
from worker.world.catalogue import default_worlds_dir
from worker.world.datasets import (
    BundledWorld,
    Dataset,
    dataset_folders,
    folder_signature,
    load_dataset,
)
from worker.world.loader import load_world
from worker.world.picture import occupancy_png

RECHECK_S = 2.0  # [s] the files' mtimes are looked at again after this long, not per request
THUMBNAILS_MAX = 512  # PNGs kept (63 worlds at a few sizes; least recently used go first)


class BundledCatalogue:
    """The data sets under `root()` (each loaded when first asked for, and again when a file
    of its folder changes: path, mtime, size), and their worlds' thumbnails. Thread-safe: the
    first requests wait for one load instead of each loading."""

    def __init__(
        self,
        root: Callable[[], Path] = default_worlds_dir,
        recheck_s: float = RECHECK_S,
        thumbnails_max: int = THUMBNAILS_MAX,
    ):
        self._root = root
        self.recheck_s = recheck_s
        self.thumbnails_max = thumbnails_max
        self._lock = threading.Lock()
        self._loaded: dict[Path, tuple[tuple, Dataset]] = {}  # folder -> (signature, data set)
        self._current: list[Dataset] = []
        self._checked = -float("inf")  # time.monotonic() of the last look at the files
        self._thumbs: OrderedDict[tuple, bytes] = OrderedDict()
        self.loads = 0  # data sets loaded so far (tests count them)

    def datasets(self) -> list[Dataset]:
        """The data sets, sorted by folder name."""
        with self._lock:
            if time.monotonic() - self._checked >= self.recheck_s:
                self._refresh()
                self._checked = time.monotonic()
            return list(self._current)

    def _refresh(self) -> None:
        loaded: dict[Path, tuple[tuple, Dataset]] = {}
        for folder in dataset_folders(Path(self._root()).resolve()):
            signature = folder_signature(folder)
            known = self._loaded.get(folder)
            if known is None or known[0] != signature:
                known = (signature, load_dataset(folder))
                self.loads += 1
            loaded[folder] = known
        self._loaded = loaded
        self._current = [d for _, d in loaded.values()]

    def dataset(self, name: str) -> Dataset:
        """The data set called `name`; NotFound if there is none (the name is compared, never
        made into a path)."""
        found = next((d for d in self.datasets() if d.name == name), None)
        if found is None:
            raise NotFound(f"no bundled data set {name[:100]!r}")
        return found

    def world(self, dataset: str, name: str) -> tuple[Dataset, BundledWorld]:
        """The data set and its world called `name`; NotFound if either does not exist."""
        d = self.dataset(dataset)
        w = d.world(name)
        if w is None:
            raise NotFound(f"no world {name[:100]!r} in the data set {d.name!r}")
        return d, w

    def licence(self, name: str) -> str:
        """The text of the data set's licence file (its source and terms), or one line saying
        it has none; NotFound for no such data set."""
        d = self.dataset(name)
        return d.licence_text() or f"{d.name}: no licence file"

    def thumbnail(self, dataset: str, name: str, max_px: int | None) -> bytes:
        """The world's picture as a PNG (see occupancy_png), made once per content and size."""
        d, w = self.world(dataset, name)
        key = (d.name, w.name, w.fingerprint, max_px)
        with self._lock:
            png = self._thumbs.get(key)
            if png is not None:
                self._thumbs.move_to_end(key)
                return png
        png = occupancy_png(w.occupancy(), max_px)  # outside the lock: others need not wait
        with self._lock:
            self._thumbs[key] = png
            while len(self._thumbs) > self.thumbnails_max:
                self._thumbs.popitem(last=False)
        return png


_CATALOGUE = BundledCatalogue()


def bundled() -> BundledCatalogue:
    """The process's catalogue of the bundled data sets (see the module's docstring)."""
    return _CATALOGUE


def import_bundled(
    session: Session,
    user: Principal,
    settings: Settings,
    dataset: str,
    name: str,
    catalogue: BundledCatalogue | None = None,
) -> tuple[World, bool]:
    """The bundled world as a world of `user`, ready at once: (the world, whether it is new).
    Stored as `mapqual run` stores a world file (content hash, facts, source path), so the
    same plan imported again, or run from the command line by the same owner, is one world.
    A new one counts against the upload quotas (429)."""
    _, bw = (catalogue or bundled()).world(dataset, name)
    world = load_world(bw.path)  # the files as they are now, in full (the catalogue keeps less)
    sha = world.fingerprint()
    mine = select(World).where(World.owner_id == user.id, World.sha256 == sha)
    existing = session.scalars(mine).first()
    if existing is not None:
        return existing, False
    quotas.check_upload(session, user.id, settings)  # 429 before anything is stored
    try:
        with session.begin_nested():  # the same import racing in: the first one stays
            row = save_world(
                session, owner_id=user.id, world=world, sha256=sha,
                source_format=bw.source_format,
            )  # fmt: skip
    except IntegrityError:
        return session.scalars(mine).one(), False
    return row, True


def imported_ids(session: Session, user: Principal) -> dict[str, int]:
    """The user's own worlds by content hash (to mark the bundled worlds already imported)."""
    rows = session.execute(select(World.sha256, World.id).where(World.owner_id == user.id))
    return {sha: wid for sha, wid in rows}
