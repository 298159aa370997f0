"""One run: world -> simulate -> explore (closed loop with SLAM) -> evaluate; `run_one`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal

from worker.evaluate.relations import AParams, BParams, SMParams
from worker.explore.params import ExploreParams
from worker.params import from_dict, to_dict
from worker.sim.simulator import SimParams
from worker.slam.params import SlamParams

Algorithm = Literal["rbpf", "odometry", "oracle"]
ALGORITHMS: tuple[str, ...] = ("rbpf", "odometry", "oracle")


@dataclass(frozen=True)
class EvalParams:
    """Evaluation: B relations are the score (thesis); A and SM are reported beside them."""

    b: BParams = field(default_factory=BParams)
    a: AParams = field(default_factory=AParams)
    sm: SMParams = field(default_factory=SMParams)
    max_gap: float = 0.1  # [s] estimate lookup: interpolate only between samples this close


@dataclass(frozen=True)
class RunParams:
    """Everything that determines a run besides the world and the seed; stored with each run."""

    algorithm: Algorithm = "rbpf"  # oracle = map and localise with the ground truth
    sim: SimParams = field(default_factory=SimParams)
    slam: SlamParams = field(default_factory=SlamParams)
    explore: ExploreParams = field(default_factory=ExploreParams)
    eval: EvalParams = field(default_factory=EvalParams)

    def to_json(self) -> dict[str, Any]:
        """Plain JSON data (`from_json` reads it back to an equal object)."""
        return to_dict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunParams:
        """Strictly validated: unknown keys, wrong types and bad values raise InputError."""
        return from_dict(cls, data)
