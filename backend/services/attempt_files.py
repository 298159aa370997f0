"""Where one attempt at a run writes its report, and what the run's row stores for it.

Local storage (today's layout): the attempt writes `<runs>/<id>.attempt-<a>/`, renamed to
`<runs>/<id>/` inside the transaction that stores the result; the row holds that path.
S3 storage: the attempt writes a scratch folder on the worker's disk, uploads it under
`runs/<id>/<a>/` before that transaction, and the transaction stores the attempt's s3:// URL:
nothing moves, so a reader sees a report only once the row points at a whole upload. An
attempt that loses deletes its objects; the winner sweeps those of attempts killed earlier.
A folder the caller owns (`mapqual run -o`, a batch) is written in place and kept; with S3
it is uploaded as well, and the row points at the upload.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from backend.store.lifecycle import attempt_dir, remove_attempt_dirs
from worker.report.folder import REPORT_ZIP, write_report_zip
from worker.storage import Storage, join
from worker.storage.local import LocalStorage


@dataclass(frozen=True)
class AttemptFiles:
    """One attempt's report: `folder` it writes on this host, `location` the row stores."""

    storage: Storage
    run_id: int
    attempt: str
    folder: Path  # where the pipeline writes
    final: Path  # local: the run's folder (own folder: the folder itself)
    own_folder: bool

    @classmethod
    def of(
        cls, storage: Storage, final: Path, run_id: int, attempt: str, own: bool
    ) -> AttemptFiles:
        """`final` the run's local folder: the caller's own (written in place), or the one
        the attempt's folder beside it is renamed to (local storage)."""
        folder = final if own else attempt_dir(final, attempt)
        return cls(storage, run_id, attempt, folder, final, own)

    @property
    def remote(self) -> bool:
        return not isinstance(self.storage, LocalStorage)

    @property
    def key(self) -> str:
        """The attempt's folder in object storage."""
        return join("runs", str(self.run_id), self.attempt)

    @property
    def location(self) -> str:
        """What the run's row holds: the upload's s3:// URL, or the local folder's path."""
        return self.storage.location(self.key) if self.remote else str(self.final)

    @property
    def rename(self) -> Path | None:
        """The folder renamed to `final` in the result's transaction (local, not owned)."""
        return None if self.remote or self.own_folder else self.folder

    def finish_folder(self) -> None:
        """After the report is written: its zip (served as it is) and, for S3, the upload."""
        if not self.own_folder:
            write_report_zip(self.folder, f"run{self.run_id}")
        if not self.remote:
            return
        self.storage.put_tree(self.key, self.folder)
        if self.own_folder:  # the caller's folder gets no zip; the stored copy does
            with tempfile.TemporaryDirectory(prefix="mapqual-zip-") as tmp:
                path = write_report_zip(self.folder, f"run{self.run_id}", Path(tmp) / REPORT_ZIP)
                self.storage.put_file(join(self.key, REPORT_ZIP), path)

    def discard(self) -> None:
        """This attempt lost: its scratch folder and its objects go (an owned folder stays)."""
        if not self.own_folder:
            shutil.rmtree(self.folder, ignore_errors=True)
        if self.remote:
            self.storage.delete_prefix(self.key)

    def sweep(self) -> None:
        """The result is stored: remove the scratch folder, and what attempts that lost
        earlier (killed, superseded) left on this disk and in the storage."""
        if not self.remote:
            remove_attempt_dirs(self.final)
            return
        if not self.own_folder:
            shutil.rmtree(self.folder, ignore_errors=True)
            remove_attempt_dirs(self.final)
        run_prefix = join("runs", str(self.run_id))
        others = {n.split("/", 1)[0] for n in self.storage.list(run_prefix)} - {self.attempt}
        for other in sorted(others):
            self.storage.delete_prefix(join(run_prefix, other))
