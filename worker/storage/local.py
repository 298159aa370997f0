"""The local-folder backend: keys are paths under one folder of this host's disk."""

from __future__ import annotations

import os
import secrets
import shutil
from pathlib import Path
from typing import BinaryIO

from worker.storage.interface import Storage, StorageError


class LocalStorage(Storage):
    """Keys under the folder `root` (made when first written)."""

    def __init__(self, root: Path):
        self.root = Path(root).resolve()
        self.url = str(self.root)

    def _path(self, key: str) -> Path:
        path = (self.root / key).resolve() if key else self.root
        if path != self.root and self.root not in path.parents:
            raise StorageError(f"key {key!r} leaves the storage folder")
        return path

    def location(self, key: str) -> str:
        return str(self._path(key))

    def local_path(self, key: str) -> Path | None:
        return self._path(key)

    def put_file(self, key: str, path: Path) -> None:
        dest = self._path(key)
        if Path(path).resolve() == dest:
            return
        self._atomic(dest, lambda tmp: shutil.copyfile(path, tmp))

    def put_bytes(self, key: str, data: bytes) -> None:
        self._atomic(self._path(key), lambda tmp: tmp.write_bytes(data))

    @staticmethod
    def _atomic(dest: Path, write) -> None:
        """Written under a temporary name and renamed: readers see a whole file or none."""
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.{secrets.token_hex(4)}.tmp")
        try:
            write(tmp)
            os.replace(tmp, dest)
        finally:
            tmp.unlink(missing_ok=True)

    def open(self, key: str) -> BinaryIO:
        return self._path(key).open("rb")

    def size(self, key: str) -> int | None:
        path = self._path(key)
        return path.stat().st_size if path.is_file() else None

    def list(self, prefix: str) -> list[str]:
        base = self._path(prefix)
        if not base.is_dir():
            return []
        return sorted(p.relative_to(base).as_posix() for p in base.rglob("*") if p.is_file())

    def delete_prefix(self, prefix: str) -> None:
        path = self._path(prefix)
        if path == self.root:
            raise StorageError("refusing to delete the whole storage folder")
        shutil.rmtree(path, ignore_errors=True)

    def check(self) -> None:
        if self.root.exists() and not self.root.is_dir():
            raise StorageError(f"runs folder {self.root} is not a folder")
        if self.root.exists() and not os.access(self.root, os.W_OK | os.X_OK):
            raise StorageError(f"runs folder {self.root} is not writable")
        if not self.root.exists() and not os.access(_existing(self.root), os.W_OK):
            raise StorageError(f"runs folder {self.root} cannot be made")


def _existing(path: Path) -> Path:
    while not path.exists():
        path = path.parent
    return path
