"""A done run's report files as the API serves them, through the storage layer (found by
`backend.services.runs.report_files`): 503 (with the reason) for files that cannot be read, files
streamed (never loaded whole), and things made on demand (a bag, a zip) built once, kept in
the storage, one build at a time per run and kind."""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import BinaryIO

from fastapi import HTTPException, status
from fastapi.responses import FileResponse, Response, StreamingResponse
from starlette.background import BackgroundTask

from backend.core.single_flight import single_flight
from backend.db.models import Run
from backend.services.errors import ServiceError
from backend.services.runs import report_files
from worker.storage import CHUNK, RunFiles, StorageError


def unavailable(run_id: int, exc: Exception) -> HTTPException:
    """503: the run is done, but its files cannot be reached now."""
    return HTTPException(
        status.HTTP_503_SERVICE_UNAVAILABLE, f"run {run_id}: its report cannot be reached ({exc})"
    )


def maybe_files(run: Run) -> RunFiles | None:
    """The done run's report folder when it can be reached now, else None (no error)."""
    try:
        return report_files(run)
    except ServiceError:
        return None


def _chunks(src: BinaryIO) -> Iterator[bytes]:
    with src:
        while block := src.read(CHUNK):
            yield block


def serve(files: RunFiles, name: str, media: str, run_id: int, filename: str | None = None,
          inline: bool = False) -> Response:  # fmt: skip
    """The file `name` of the folder: from the disk as it is, or streamed from object storage
    (its size known up front, so clients see a Content-Length and a progress bar)."""
    path = files.local_path(name)
    if path is not None:
        if not path.is_file():
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run_id} has no {name}")
        disposition = "inline" if inline else "attachment"
        return FileResponse(path, media_type=media, filename=filename,
                            content_disposition_type=disposition)  # fmt: skip
    try:
        size = files.size(name)
        if size is None:
            raise HTTPException(status.HTTP_404_NOT_FOUND, f"run {run_id} has no {name}")
        src = files.open(name)
    except (StorageError, OSError) as exc:
        raise unavailable(run_id, exc) from None
    headers = {"Content-Length": str(size)}
    if filename:
        kind = "inline" if inline else "attachment"
        headers["Content-Disposition"] = f'{kind}; filename="{filename}"'
    return StreamingResponse(_chunks(src), media_type=media, headers=headers)


def _current(files: RunFiles, name: str, source: str | None) -> bool:
    """`name` is there, and (a folder on this disk, where a file may be rewritten in place)
    not older than the file `source` it was built from. Object storage keeps each run's
    files under its attempt's key, never rewritten: there it is enough that it exists."""
    if not files.has(name):
        return False
    path, src = files.local_path(name), source and files.local_path(source)
    if path is None or not src or not src.is_file():
        return True
    return path.stat().st_mtime_ns >= src.stat().st_mtime_ns


def built(files: RunFiles, name: str, database_url: str, build: Callable[[Path], Path],
          media: str, run_id: int, filename: str,
          source: str | None = None) -> Response:  # fmt: skip
    """The file `name` of the folder, built by `build(work folder) -> file` when missing (or
    older than its `source` file, on a local disk): once, by one request at a time per run
    and name (the others wait, then serve the kept file), kept in the storage. Where the
    folder cannot be written (a read-only disk), built for this response only and deleted
    afterwards."""
    if _current(files, name, source):
        return serve(files, name, media, run_id, filename)
    with single_flight(database_url, f"{files.location}::{name}"):
        fresh = RunFiles(files.storage, files.prefix)  # listed again: another may have built it
        if _current(fresh, name, source):
            return serve(fresh, name, media, run_id, filename)
        work = Path(tempfile.mkdtemp(prefix="mapqual-build-"))
        path: Path | None = None
        try:
            path = build(work)
            fresh.put_file(name, path)
        except StorageError as exc:
            shutil.rmtree(work, ignore_errors=True)
            raise unavailable(run_id, exc) from None
        except OSError as exc:  # a read-only report folder: this response only
            if path is None:
                shutil.rmtree(work, ignore_errors=True)
                raise unavailable(run_id, exc) from None
            cleanup = BackgroundTask(shutil.rmtree, work, ignore_errors=True)
            return FileResponse(path, media_type=media, filename=filename, background=cleanup)
        except BaseException:
            shutil.rmtree(work, ignore_errors=True)
            raise
        shutil.rmtree(work, ignore_errors=True)
    return serve(fresh, name, media, run_id, filename)
