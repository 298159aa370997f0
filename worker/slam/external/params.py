"""ExternalSlamParams: which program to run as the SLAM of a run, and its time-outs, with units."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from worker.errors import InputError

MAX_NAME = 31  # [characters] of a program's name


@dataclass(frozen=True)
class ExternalSlamParams:
    """An external SLAM program (`slam: {external: {name: ..., command: [...]}}` in --params).

    The command is run without a shell, its stdin / stdout carry the protocol's frames and its
    stderr is kept for the failure message. Over the API users give only `name`: the server
    fills the command in from the administrator's list (MAPQUAL_EXTERNAL_SLAM), so a stored run
    holds the command it ran.
    """

    name: str = "external"  # what the program is called in reports (a short identifier)
    command: tuple[str, ...] = ()  # argv; the first element is the executable
    start_timeout_s: float = 30.0  # [s] wall time allowed for start-up and the handshake
    step_timeout_s: float = 10.0  # [s] wall time allowed for one step's answer
    close_timeout_s: float = 2.0  # [s] wall time allowed to exit after "bye", then killed
    # Limits on the program: address space [MiB] and CPU time [s]; None: none (stored runs
    # of the CLI). Over the API the server fills them in from its settings (users cannot).
    memory_mb: int | None = field(default=None, metadata={"omit_if_none": True})
    cpu_s: int | None = field(default=None, metadata={"omit_if_none": True})

    def __post_init__(self) -> None:
        if not self.name or not self.name.replace("-", "_").isidentifier():
            raise InputError(
                f"slam.external.name {self.name!r} must be an identifier (letters, digits, _, -)"
            )
        if len(self.name) > MAX_NAME:  # external:NAME fits the database's 40 characters
            raise InputError(f"slam.external.name {self.name!r} is longer than {MAX_NAME} letters")
        if any(not isinstance(a, str) or "\0" in a for a in self.command):
            raise InputError("slam.external.command must be a list of strings without NUL bytes")
        if self.command and not self.command[0]:
            raise InputError("slam.external.command[0] (the program) must not be empty")
        for key in ("memory_mb", "cpu_s"):
            value = getattr(self, key)
            if value is None:
                continue
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise InputError(f"slam.external.{key} must be a whole number >= 1, got {value}")
        for key in ("start_timeout_s", "step_timeout_s", "close_timeout_s"):
            value = getattr(self, key)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"slam.external.{key} must be a positive number [s], got {value}")
