"""The storage interface (`Storage`) that both backends implement, its error and key joining."""

from __future__ import annotations

import shutil
from abc import ABC, abstractmethod
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

CHUNK = 1 << 20  # [bytes] streamed at a time: big enough for 50 MB/s+, small in memory


class StorageError(RuntimeError):
    """The storage cannot be reached or refused the request; the message says why, in one line."""


class Storage(ABC):
    """A flat store of byte objects under '/'-separated keys."""

    url: str  # where it is, for messages and for the locations rows hold

    @abstractmethod
    def location(self, key: str) -> str:
        """What a row stores to find `key` again (an s3:// URL, or a local path)."""

    @abstractmethod
    def put_file(self, key: str, path: Path) -> None:
        """Store the file `path` as `key` (whole or not at all, as readers see it)."""

    @abstractmethod
    def put_bytes(self, key: str, data: bytes) -> None:
        """Store `data` as `key`."""

    @abstractmethod
    def open(self, key: str) -> BinaryIO:
        """A readable stream of `key`; FileNotFoundError when there is none."""

    @abstractmethod
    def size(self, key: str) -> int | None:
        """The size of `key` [bytes], None when there is none."""

    @abstractmethod
    def list(self, prefix: str) -> list[str]:
        """Every key under the folder `prefix`, relative to it, sorted."""

    @abstractmethod
    def delete_prefix(self, prefix: str) -> None:
        """Delete every key under the folder `prefix` (nothing there is fine)."""

    @abstractmethod
    def check(self) -> None:
        """Raise StorageError unless the storage answers (readiness)."""

    def local_path(self, key: str) -> Path | None:
        """The file of `key` on this host's disk, for a local store; None otherwise."""
        return None

    def put_tree(self, prefix: str, folder: Path) -> list[str]:
        """Store every file under `folder` as `prefix/<relative path>`; the keys written."""
        keys = []
        for path in sorted(p for p in folder.rglob("*") if p.is_file()):
            key = join(prefix, path.relative_to(folder).as_posix())
            self.put_file(key, path)
            keys.append(key)
        return keys

    def get_file(self, key: str, dest: Path) -> Path:
        """Copy `key` to the file `dest` (streamed); FileNotFoundError when there is none."""
        dest.parent.mkdir(parents=True, exist_ok=True)
        with self.open(key) as src, dest.open("wb") as out:
            shutil.copyfileobj(src, out, CHUNK)
        return dest

    def iter_bytes(self, key: str, chunk: int = CHUNK) -> Iterator[bytes]:
        """`key` in chunks of `chunk` bytes, for a streamed response."""
        with self.open(key) as src:
            while block := src.read(chunk):
                yield block


def join(*parts: str) -> str:
    """Keys joined with '/', empty parts dropped."""
    return "/".join(p.strip("/") for p in parts if p and p.strip("/"))
