"""A run's report folder wherever it is: what a row's location names, read and written
through the storage layer by every reader (API, dashboard, CLI, batch tables)."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO

from worker.storage.interface import Storage, StorageError, join


@dataclass
class RunFiles:
    """The files under `prefix` of `storage` (a run's report, an estimate's folder)."""

    storage: Storage
    prefix: str
    _names: list[str] | None = field(default=None, repr=False)

    @property
    def location(self) -> str:
        return self.storage.location(self.prefix)

    def key(self, name: str) -> str:
        return join(self.prefix, name)

    def names(self) -> list[str]:
        """Every file of the folder (relative names, sorted); listed once, then remembered."""
        if self._names is None:
            self._names = self.storage.list(self.prefix)
        return self._names

    def check(self) -> None:
        """StorageError (with the reason) unless the folder is there and holds files."""
        if not self.names():
            raise StorageError(f"report folder {self.location} is missing or empty")

    def has(self, name: str) -> bool:
        return name in self.names()

    def open(self, name: str) -> BinaryIO:
        return self.storage.open(self.key(name))

    def read_bytes(self, name: str) -> bytes:
        with self.open(name) as f:
            return f.read()

    def size(self, name: str) -> int | None:
        return self.storage.size(self.key(name))

    def iter_bytes(self, name: str) -> Iterator[bytes]:
        return self.storage.iter_bytes(self.key(name))

    def local_path(self, name: str) -> Path | None:
        """The file on this host's disk (a local folder), else None: fetch() it."""
        return self.storage.local_path(self.key(name))

    def put_file(self, name: str, path: Path) -> None:
        self.storage.put_file(self.key(name), path)
        self._names = None

    def put_tree(self, name: str, folder: Path) -> None:
        self.storage.put_tree(self.key(name), folder)
        self._names = None

    def fetch(self, names: Iterable[str], dest: Path) -> Path:
        """The files `names` (those there) copied into the folder `dest`, which is returned."""
        dest.mkdir(parents=True, exist_ok=True)
        for name in names:
            if self.has(name):
                self.storage.get_file(self.key(name), dest / name)
        return dest

    def sub(self, name: str) -> RunFiles:
        """The sub-folder `name`."""
        return RunFiles(self.storage, self.key(name))


def run_files(location: str) -> RunFiles:
    """The folder a row's location names: an s3://bucket/key URL, or a folder on this disk."""
    if location.startswith("s3://"):
        from worker.storage.s3 import S3Storage

        bucket, _, key = location.removeprefix("s3://").partition("/")
        return RunFiles(S3Storage(bucket), key)
    from worker.storage.local import LocalStorage

    return RunFiles(LocalStorage(Path(location)), "")
