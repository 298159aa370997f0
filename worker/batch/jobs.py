"""A batch's plan in the database's terms: one job per world and condition (every parameter
but the seed), one run per seed, each job named by an idempotency key so a resumed batch
finds its jobs again."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from worker.batch.experiment import RunSpec


def cell_key(spec: RunSpec) -> str:
    """A job's identity inside a batch: the world and every parameter, all but the seed."""
    doc = json.dumps([spec.world_path, spec.world, spec.params], sort_keys=True)
    return hashlib.sha256(doc.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Cell:
    """One job of a batch: the runs that differ by their seed only."""

    key: str  # cell_key of its runs
    specs: tuple[RunSpec, ...]  # in the batch's order

    @property
    def world_path(self) -> str:
        """The floorplan file of the job's world."""
        return self.specs[0].world_path

    @property
    def slam(self) -> str:
        """The job's SLAM algorithm."""
        return self.specs[0].slam

    @property
    def params(self) -> dict[str, Any]:
        """The job's RunParams as JSON."""
        return self.specs[0].params

    @property
    def seeds(self) -> list[int]:
        """The seeds of its runs, one run each."""
        return [s.seed for s in self.specs]

    def idempotency_key(self, batch_id: str) -> str:
        """The key the job is stored under, for this batch."""
        return f"batch:{batch_id}:{self.key}"


def plan_cells(specs: Sequence[RunSpec]) -> list[Cell]:
    """The batch's runs grouped into jobs, in the order of each job's first run."""
    cells: dict[str, list[RunSpec]] = {}
    for spec in specs:
        cells.setdefault(cell_key(spec), []).append(spec)
    return [Cell(key, tuple(group)) for key, group in cells.items()]


def source_format(world_path: str) -> str:
    """How a batch's world file is stored: a Stage world or a map_server YAML."""
    return "stage" if world_path.endswith(".world") else "yaml"
