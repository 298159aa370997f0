"""Where run artifacts live: one interface (`Storage`), two backends chosen by one setting
(`MAPQUAL_STORAGE`): a local folder (the default, the embedded case) or S3-compatible object
storage (`s3://bucket/prefix`: AWS S3, MinIO, Ceph RGW), configured the standard way
(AWS_ENDPOINT_URL, AWS_ACCESS_KEY_ID, AWS_SECRET_ACCESS_KEY, AWS_REGION).

A run's row holds its report's *location*: an `s3://bucket/key` URL, or (the local backend,
and rows written before this layer) a folder path on the disk of the host that reads it.
`run_files(location)` opens either. Nothing here imports `backend/`: workers use it as is. The
interface is in `interface`, which the backends import (this module imports them).
"""

from __future__ import annotations

from pathlib import Path

from worker.storage.files import RunFiles, run_files
from worker.storage.interface import CHUNK, Storage, StorageError, join


def check_setting(value: str) -> str:
    """The storage setting as given, or ValueError with one line: '' / 'local' (the runs
    folder) or s3://bucket[/prefix]."""
    if value in ("", "local"):
        return value
    if not value.startswith("s3://") or not value[5:].split("/", 1)[0]:
        raise ValueError(f"MAPQUAL_STORAGE must be 'local' or s3://bucket[/prefix], not {value!r}")
    return value


def open_storage(setting: str, runs_dir: Path) -> Storage:
    """The storage the setting names: the folder `runs_dir` ('' or 'local'), or S3."""
    from worker.storage.local import LocalStorage

    if check_setting(setting) in ("", "local"):
        return LocalStorage(Path(runs_dir))
    from worker.storage.s3 import S3Storage

    return S3Storage.from_url(setting)


__all__ = ["CHUNK", "RunFiles", "Storage", "StorageError", "join", "open_storage", "run_files"]
