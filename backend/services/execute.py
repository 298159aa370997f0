"""The one run service: a stored run executed exactly once. Claim it under a new attempt, run
the pipeline into the attempt's own folder, and keep the result (or the failure) only while
the attempt still holds the run; an attempt that lost keeps nothing and deletes its folder.

The Celery task, `mapqual run` and both modes of `mapqual batch` are shells around
`execute_run`; they differ only in their `Placement` and in who hears of the progress.
"""

from __future__ import annotations

import logging
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

from backend.core.config import Settings
from backend.db.models import Run, World
from backend.db.session import session_scope
from backend.services.attempt_files import AttemptFiles
from backend.services.progress import ProgressReporter
from backend.store import mark_run_failed, store_run_result, world_model
from backend.store.lifecycle import TransitionRefused, claim_run, new_attempt
from worker.report.folder import SIM_LOG
from worker.report.summary import RunSummary
from worker.status import RunStatus
from worker.storage import StorageError

if TYPE_CHECKING:  # the pipeline (numba) loads only when a run is executed
    from redis import Redis

    from worker.pipeline import RunProgress, RunResult
    from worker.run_params import RunParams
    from worker.world.world import World as WorldModel

log = logging.getLogger("mapqual.execute")
# besides the run's status when the delivery ended it: done | cancelled | failed
Kind = Literal["busy", "skipped", "lost"] | RunStatus


@dataclass(frozen=True)
class Outcome:
    """What became of a delivery: `busy` means another attempt is alive and the delivery
    should come back later; every other kind is final for this delivery."""

    kind: Kind
    message: str
    summary: RunSummary | None = field(default=None, compare=False)  # done: the summary
    report_dir: str | None = None  # done: where its report folder is
    found: str | None = None  # skipped: the status the run had (done, cancelled, failed, missing)
    error: str | None = None  # failed: the error stored with the run


@dataclass(frozen=True)
class Placement:
    """Where a run's report goes, and how the run treats its folder and its database row."""

    report_dir: Path | None = None  # the run's folder; None: <runs_dir>/<run id>/
    # False: written in the attempt's own folder with its report.zip, renamed into place with
    # the commit of the result (a worker's run). True: written straight into `report_dir`, a
    # folder the caller owns and keeps whatever happens (`mapqual run -o`, a batch's
    # OUT/runs/<key>/), with no zip (the API makes one if it is asked for it).
    own_folder: bool = False
    sim_log: str | None = SIM_LOG  # file name of the CARMEN log in the folder; None: none
    # a running run silent this long [s] is taken over; None: the settings' run lease
    lease_s: float | None = None
    # a KeyboardInterrupt or SystemExit marks the run failed (a command in the foreground);
    # a worker's leaves the run to its lease and the broker's redelivery
    fail_on_interrupt: bool = False


WORKER = Placement()


def execute_run(
    run_id: int,
    settings: Settings,
    redis_client: Redis | None = None,
    *,
    place: Placement = WORKER,
    on_progress: Callable[[RunProgress], None] | None = None,
    world: WorldModel | None = None,
) -> Outcome:
    """Claim, run, and store run `run_id` (see the module's docstring). Progress goes to
    `on_progress`, or (None) to the database and Redis, where cancellation is noticed;
    `world` is the run's world already loaded (None: read from the database)."""
    from worker.pipeline import RunCancelled, RunSuperseded
    from worker.run_params import RunParams

    url, attempt = settings.database_url, new_attempt()
    lease_s = settings.run_lease_s if place.lease_s is None else place.lease_s
    with session_scope(url) as s:
        answer, run = claim_run(s, run_id, attempt, lease_s)
        if run is None:
            kind: Kind = "busy" if answer == "busy" else "skipped"
            return Outcome(kind, f"run {run_id}: not run ({answer})", found=answer)
        world = world if world is not None else world_model(s.get_one(World, run.world_id))
        params, seed = RunParams.from_json(run.params), run.seed
    final = (place.report_dir or settings.runs_dir / str(run_id)).resolve()
    try:
        storage = settings.open_storage()
    except StorageError as exc:  # e.g. a malformed AWS_ENDPOINT_URL: the run fails, saying so
        with session_scope(url) as s:
            mark_run_failed(s, run_id, str(exc), attempt)
        return Outcome(RunStatus.FAILED, f"run {run_id}: failed ({exc})", error=str(exc))
    files = AttemptFiles.of(storage, final, run_id, attempt, place.own_folder)
    if on_progress is None:
        on_progress = ProgressReporter(url, run_id, redis_client, attempt=attempt)
    job = _Job(url, run_id, attempt, files, place)
    try:
        result = job.run_and_store((world, params, seed), on_progress)
    except RunSuperseded as exc:
        return job.lost("lost", f"run {run_id}: {exc}")
    except RunCancelled:
        return job.lost(RunStatus.CANCELLED, f"run {run_id}: cancelled")
    except TransitionRefused as exc:
        return job.lost("lost", f"run {run_id}: result not stored ({exc})")
    except Exception as caught:  # SoftTimeLimitExceeded included: the run failed, not the worker
        exc = signalled(caught)
        if not isinstance(exc, Exception):  # an interrupt that came inside numba's dispatcher
            if place.fail_on_interrupt:
                job.failed(f"{type(exc).__name__}: {exc}")
            raise exc from caught
        log.exception("run %s failed", run_id)
        return job.failed(f"{type(exc).__name__}: {exc}")
    except BaseException as exc:
        if place.fail_on_interrupt:
            job.failed(f"{type(exc).__name__}: {exc}")
        raise
    _sweep(files, run_id)
    summary = result.summary
    return Outcome(RunStatus.DONE, f"run {run_id}: {summary.outcome}", summary, files.location)


def _sweep(files: AttemptFiles, run_id: int) -> None:
    """Remove what attempts that lost earlier (killed ones) left; where storage refuses, the
    result is stored all the same and the leftovers wait for the next sweep."""
    try:
        files.sweep()
    except StorageError as exc:
        log.warning("run %s: leftovers of earlier attempts not removed (%s)", run_id, exc)


def signalled(exc: BaseException) -> BaseException:
    """The exception a run really ended with. One a signal handler raises (Celery's soft time
    limit, an interrupt) while numba's dispatcher is running comes out wrapped in
    SystemError ("... returned a result with an exception set"), the handler's exception as
    its cause; that cause is what the run's error says."""
    seen: set[int] = set()
    while isinstance(exc, SystemError) and id(exc) not in seen:
        seen.add(id(exc))
        inner = exc.__cause__ or exc.__context__
        if inner is None:
            break
        exc = inner
    return exc


@dataclass(frozen=True)
class _Job:
    """One attempt at one run: where it writes, and how it ends."""

    url: str
    run_id: int
    attempt: str
    files: AttemptFiles  # where the attempt writes its report, and where it is kept
    place: Placement

    def run_and_store(
        self,
        job: tuple[WorldModel, RunParams, int],
        on_progress: Callable[[RunProgress], None],
    ) -> RunResult:
        """Run the pipeline on `job` = (world, RunParams, seed) writing into the folder, write
        the report there (and upload it, S3), and store the result as this attempt's in one
        transaction, the local folder renamed into place inside it. The `RunResult`;
        TransitionRefused when the attempt no longer holds the run."""
        from worker.pipeline import run_one
        from worker.report.folder import write_report
        from worker.slam.threads import with_process_threads

        world, params, seed = job
        params = with_process_threads(params)  # the cores a lone run was given; same result
        folder = self.files.folder
        log_path = folder / self.place.sim_log if self.place.sim_log else None
        result = run_one(world, params, seed, on_progress, sim_log=log_path)
        write_report(result, folder)
        self.files.finish_folder()  # its zip; with S3 the upload, before the commit below
        ex = result.exploration
        with session_scope(self.url) as s:
            store_run_result(
                s, self.run_id, summary=result.summary, t=ex.t, pose_gt=ex.pose_gt,
                pose_est=ex.pose_est, map_ros=ex.final_map.to_ros(),
                map_resolution=ex.final_map.resolution, map_origin=ex.final_map.origin,
                report_dir=self.files.location, attempt=self.attempt, folder=self.files.rename,
            )  # fmt: skip
        return result

    def lost(self, kind: Kind, message: str) -> Outcome:
        """This attempt no longer holds the run: it keeps nothing (of its own folder)."""
        self._discard()
        log.info("%s", message)
        return Outcome(kind, message)

    def failed(self, error: str) -> Outcome:
        """Mark the run failed if this attempt still holds it (a cancelled run stays cancelled)."""
        self._discard()
        run_id = self.run_id
        with session_scope(self.url) as s:
            if not mark_run_failed(s, run_id, error, self.attempt):
                return Outcome(
                    "lost", f"run {run_id}: failed, but no longer this attempt's ({error})"
                )
            # a run folder there now is the leftover of an interrupted rename-and-commit
            if self.files.rename and s.get_one(Run, run_id).status != RunStatus.DONE:
                shutil.rmtree(self.files.final, ignore_errors=True)
        return Outcome(RunStatus.FAILED, f"run {run_id}: failed ({error})", error=error)

    def _discard(self) -> None:
        try:
            self.files.discard()
        except StorageError as exc:  # never referenced by the row: swept by the next winner
            log.warning("run %s: attempt %s not removed (%s)", self.run_id, self.attempt, exc)
