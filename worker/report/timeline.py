"""A run's figures against simulated time (timeline.csv in its report folder): what the viewer
shows beside the scene as a replay follows its timeline, recorded from the run's progress.

One row per progress report (`ExploreParams.progress_period`, 1 s of simulated time):
  t_s            [s] simulated time
  coverage       [0, 1] the coverage estimate of that moment (refreshed every
                 `coverage_period`; the rows between carry the last estimate, as the live
                 viewer showed it)
  goals_reached  frontier goals reached or explored so far
  status         what the navigation stack was doing
Wall-clock figures (the real-time factor) are left out: the same run gives the same file.
"""

from __future__ import annotations

import bisect
import csv
import io
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

TIMELINE = "timeline.csv"
HEADER = ("t_s", "coverage", "goals_reached", "status")


@dataclass
class Timeline:
    """The series, growing as the run reports its progress."""

    t: list[float] = field(default_factory=list)
    coverage: list[float] = field(default_factory=list)
    goals: list[int] = field(default_factory=list)
    status: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.t)

    def add(self, t: float, coverage: float, goals_reached: int, status: str) -> None:
        self.t.append(float(t))
        self.coverage.append(float(coverage))
        self.goals.append(int(goals_reached))
        self.status.append(str(status))

    def tap(self, on_progress: Callable[[Any], None]) -> Callable[[Any], None]:
        """`on_progress` with each report (a `worker.pipeline.RunProgress`) recorded first."""

        def record(p: Any) -> None:
            self.add(p.t, p.coverage, p.goals_reached, p.status)
            on_progress(p)

        return record

    def to_csv(self) -> str:
        out = io.StringIO()
        w = csv.writer(out, lineterminator="\n")
        w.writerow(HEADER)
        for row in zip(self.t, self.coverage, self.goals, self.status, strict=True):
            w.writerow((f"{row[0]:.3f}", f"{row[1]:.4f}", row[2], row[3]))
        return out.getvalue()

    def write(self, path: str | Path) -> None:
        Path(path).write_text(self.to_csv(), encoding="utf-8")

    @classmethod
    def from_csv(cls, text: str) -> Timeline:
        """The series of a timeline.csv; ValueError when it is not one."""
        rows = list(csv.reader(io.StringIO(text)))
        if not rows or tuple(rows[0]) != HEADER:
            raise ValueError(f"not a {TIMELINE}: its header is {rows[:1]!r}")
        tl = cls()
        for row in rows[1:]:
            if len(row) != len(HEADER):
                raise ValueError(f"a {TIMELINE} row of {len(row)} fields: {row!r}")
            tl.add(float(row[0]), float(row[1]), int(row[2]), row[3])
        return tl

    def at(self, t: float) -> dict[str, Any] | None:
        """The figures of the last report at or before `t`; None before the first one."""
        i = bisect.bisect_right(self.t, t + 1e-9) - 1
        if i < 0:
            return None
        return {
            "coverage": self.coverage[i],
            "goals_reached": self.goals[i],
            "status": self.status[i],
            "t_report": self.t[i],
        }
