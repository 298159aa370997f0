"""Errors the pipeline raises for bad user input (shown as one line, CLI exit code 2)."""

from __future__ import annotations

from pathlib import Path


class InputError(ValueError):
    """Bad input from the user: a file, a parameter, a floorplan.

    The message is complete on its own (it names the file and line where there is one),
    because the CLI prints it as a single line and the API returns it as a 4xx body.
    """

    def __init__(self, message: str, path: str | Path | None = None, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        super().__init__(f"{where}{message}")


class InputWarning(UserWarning):
    """Input that was read with a documented repair (out-of-order samples sorted, a truncated
    last line skipped, a degenerate clock replaced); the message is one complete line."""


class SlamFailed(RuntimeError):
    """The SLAM algorithm cannot go on (an external program crashed, stalled or broke the
    protocol): the run ends failed with reason `slam_failed`. The message is one line that
    names the step; `stderr_tail` holds the program's last stderr lines (may be empty)."""

    def __init__(self, message: str, step: int | None = None, stderr_tail: str = ""):
        self.step = step
        self.stderr_tail = stderr_tail
        super().__init__(message)
