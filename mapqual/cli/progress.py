"""Progress on the terminal: a rich bar on stderr while a command works (none when quiet or
when stderr is not a terminal), shared by `mapqual run` and `mapqual slam`."""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.progress import ProgressColumn

    from worker.pipeline import RunProgress


class TerminalBar:
    """A rich bar with `columns` (made only on a terminal, so rich loads only there), started
    and stopped by `with`; `update` moves it."""

    def __init__(
        self,
        quiet: bool,
        columns: Callable[[], Sequence[str | ProgressColumn]],
        description: str,
        **fields: Any,
    ):
        self.quiet = quiet
        self.bar = None
        if sys.stderr.isatty() and not quiet:
            from rich.progress import Progress as RichProgress

            self.bar = RichProgress(*columns(), transient=True)
            self.task = self.bar.add_task(description, **fields)

    def __enter__(self) -> TerminalBar:
        if self.bar is not None:
            self.bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.bar is not None:
            self.bar.stop()

    def update(self, **fields: Any) -> None:
        if self.bar is not None:
            self.bar.update(self.task, **fields)


def _scan_columns() -> list[str | ProgressColumn]:
    from rich.progress import BarColumn, MofNCompleteColumn, TimeElapsedColumn

    return ["[bold]slam", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn()]


class ScanBar(TerminalBar):
    """`mapqual slam`: scans done of the log's."""

    def __init__(self, quiet: bool):
        super().__init__(quiet, _scan_columns, "slam", total=None)

    def __call__(self, done: int, total: int) -> None:
        self.update(completed=done, total=total)


def _run_columns() -> list[str | ProgressColumn]:
    from rich.progress import BarColumn, TextColumn, TimeElapsedColumn

    return [
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.completed:>6.0f}/{task.total:.0f} s sim"),
        TextColumn("coverage {task.fields[cov]:>4.0%}  x{task.fields[rtf]:.0f} real time"),
        TimeElapsedColumn(),
    ]


class RunBar(TerminalBar):
    """`mapqual run`: simulated time of the limit, coverage and speed; without a terminal, a
    plain line each simulated minute (unless quiet)."""

    def __init__(self, time_limit: float, quiet: bool):
        super().__init__(quiet, _run_columns, "exploring", total=time_limit, cov=0.0, rtf=0.0)
        self.next_line = 60.0  # [s] simulated time of the next plain line

    def __call__(self, p: RunProgress) -> None:
        if self.bar is not None:
            self.update(completed=p.t, cov=p.coverage, rtf=p.rtf)
        elif not self.quiet and p.t >= self.next_line:
            self.next_line += 60.0
            print(
                f"t={p.t:7.0f} s  coverage {p.coverage:4.0%}  x{p.rtf:.0f} real time  {p.status}",
                file=sys.stderr,
                flush=True,
            )
