"""The vocabularies of a run's and a job's life: statuses, outcomes, stop reasons, records.

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


class RunReason(StrEnum):
    """Why a run's exploration stopped: the stop rule that fired (the summary's `stop`, and its
    `reason` when the run failed). The first two complete a run, the others fail it."""

    NO_FRONTIER = "no_frontier"  # no reachable frontier left
    MAP_UNCHANGED = "map_unchanged"  # two map snapshots a period apart differ by little
    COLLISION = "collision"  # the simulator reports a contact
    STUCK = "stuck"  # goals given up in a row, or the robot stopped moving
    TIME_LIMIT = "time_limit"  # the simulated time limit reached
    SLAM_DIVERGED = "slam_diverged"  # the SLAM pose too far from the ground truth
    SLAM_FAILED = "slam_failed"  # the SLAM program crashed, stalled or broke its protocol

    @property
    def outcome(self) -> RunOutcome:
        """completed for the rules that find nothing left to explore, else failed (a run the
        loop then finds incomplete is decided from its map, not from this)."""
        return RunOutcome.COMPLETED if self in COMPLETED_REASONS else RunOutcome.FAILED


class WorldStatus(StrEnum):
    """Where an uploaded world stands: analysed off the request thread, then ready or not."""

    PENDING = "pending"  # stored, being analysed: no geometry yet
    READY = "ready"  # analysed: runs may use it
    INVALID = "invalid"  # the loader refused its files (see its error)


class RecordStatus(StrEnum):
    """A batch record's state: the pipeline finished the run (whatever its outcome), or the
    run raised (the tables count it as failed with reason `RecordStatus.ERROR`, "error")."""

    DONE = "done"
    ERROR = "error"


# the statuses a run or a job leaves only by being worked on or cancelled
ACTIVE_RUN = frozenset({RunStatus.QUEUED, RunStatus.RUNNING})
ACTIVE_JOB = frozenset({JobStatus.QUEUED, JobStatus.RUNNING})
FINISHED_RUN = frozenset({RunStatus.DONE, RunStatus.FAILED, RunStatus.CANCELLED})
# the stop reasons of a completed exploration
COMPLETED_REASONS = frozenset({RunReason.NO_FRONTIER, RunReason.MAP_UNCHANGED})
