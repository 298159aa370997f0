"""The vocabularies of a run's and a job's life: statuses, outcomes, batch record states.

One `StrEnum` each, in a module that imports nothing of mapqual's (no numba, no database), so
that the API, the dashboard, the viewer, the CLI and the batch tables all compare against the
same members. Members are `str`s: the database and JSON hold exactly these strings, and a
plain string read back compares equal to its member (`RunStatus.DONE == "done"`).
"""

from __future__ import annotations

from enum import StrEnum


class RunStatus(StrEnum):
    """Where a run is in its life: queued, running (an attempt holds it), done (see its
    outcome), failed (an internal error) or cancelled."""

    QUEUED = "queued"  # waiting for a worker
    RUNNING = "running"  # an attempt holds it
    DONE = "done"  # the pipeline finished: see its outcome
    FAILED = "failed"  # an internal error (not a failed exploration, which is done)
    CANCELLED = "cancelled"  # by its owner; final


class JobStatus(StrEnum):
    """A job's status, which follows its runs': running while any runs (or some are finished
    and some queued), failed when nothing is left to run and some run failed, else done."""

    QUEUED = "queued"  # every run queued
    RUNNING = "running"  # some run running, or some finished and some still queued
    DONE = "done"  # every run done (or cancelled)
    FAILED = "failed"  # nothing left to run, and some run failed
    CANCELLED = "cancelled"  # by its owner; final


class RunOutcome(StrEnum):
    """What a done run's exploration achieved (its `reason` says why it stopped)."""

    COMPLETED = "completed"  # nothing left to explore
    FAILED = "failed"  # collision, stuck, time limit, SLAM diverged, ...
    # stopped as done (no frontier, map unchanged) with space left that the robot could reach
    # in the floorplan but never saw: frontiers given up (blacklisted, unreachable in the map)
    INCOMPLETE = "incomplete"


class WorldStatus(StrEnum):
    """Where an uploaded world stands: analysed off the request thread, then ready or not."""

    PENDING = "pending"  # stored, being analysed: no geometry yet
    READY = "ready"  # analysed: runs may use it
    INVALID = "invalid"  # the loader refused its files (see its error)


class RecordStatus(StrEnum):
    """A batch record's state: the pipeline finished the run (whatever its outcome), or the
    run raised (the tables count it as failed with reason "error")."""

    DONE = "done"
    ERROR = "error"


# the statuses a run or a job leaves only by being worked on or cancelled
ACTIVE_RUN = frozenset({RunStatus.QUEUED, RunStatus.RUNNING})
ACTIVE_JOB = frozenset({JobStatus.QUEUED, JobStatus.RUNNING})
FINISHED_RUN = frozenset({RunStatus.DONE, RunStatus.FAILED, RunStatus.CANCELLED})
