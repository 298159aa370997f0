"""RunParams and EvalParams: everything that sets a run up besides the world and the seed.

Light on purpose: these modules import no numba kernel, so the API validates a job's params
(and publishes their JSON Schema) without loading the numeric stack.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Annotated, Any

from pydantic import AfterValidator, Field

from worker.errors import InputError
from worker.evaluate.params import AParams, BParams, SMParams
from worker.explore.params import ExploreParams, nest_flat
from worker.params import adapter, from_dict, to_dict
from worker.sim.params import FOOTPRINT_M, SimParams
from worker.slam import registry
from worker.slam.params import SlamParams, with_defaults_for
from worker.slam.realtime_params import MODELLED, RealtimeParams

# A registered SLAM algorithm's name: checked against the registry when it is read, listed as
# an enum in the JSON Schema.
Algorithm = Annotated[
    str, AfterValidator(registry.check_name), Field(json_schema_extra=registry.add_enum)
]


@dataclass(frozen=True)
class EvalParams:
    """Evaluation: B relations are the score (thesis); A and SM are reported beside them."""

    b: BParams = field(default_factory=BParams)
    a: AParams = field(default_factory=AParams)
    sm: SMParams = field(default_factory=SMParams)
    max_gap: float = 0.1  # [s] estimate lookup: interpolate only between samples this close


@dataclass(frozen=True)
class RunParams:
    """Everything that determines a run besides the world and the seed; stored with each run.

    The robot's size is set once, by `sim.footprint` [m]; the exploration's
    costmap.footprint_half_m is derived from it here (it is stored, for the record, but cannot
    be set on its own).
    """

    algorithm: Algorithm = "rbpf"  # a name in worker.slam.registry (oracle = ground truth)
    sim: SimParams = field(default_factory=SimParams)
    slam: SlamParams = field(default_factory=SlamParams)
    explore: ExploreParams = field(default_factory=ExploreParams)
    eval: EvalParams = field(default_factory=EvalParams)
    # None: every SLAM update is instant (the default); set: it takes simulated time and
    # scans that arrive meanwhile are dropped (worker.slam.realtime)
    realtime: RealtimeParams | None = None

    def __post_init__(self) -> None:
        if not self.sim.footprint > 0:  # SimParams refuses it too; RunParams relies on it
            raise InputError(f"sim.footprint must be > 0 [m], got {self.sim.footprint}")
        if self.explore.costmap.footprint_half_m != 0.5 * self.sim.footprint:
            object.__setattr__(self, "explore", self.explore.with_footprint(self.sim.footprint))
        rt = self.realtime
        if rt is not None and rt.fixed_latency_s is None and self.algorithm not in MODELLED:
            raise InputError(
                f"realtime: no cost model for SLAM algorithm {self.algorithm!r} (models: "
                f"{', '.join(MODELLED)}); give realtime.fixed_latency_s instead"
            )
        if rt is not None and self.algorithm in ("oracle", "external"):
            raise InputError(f"realtime does not apply to SLAM algorithm {self.algorithm!r}")
        # a graph run stores the graph SLAM settings it ran with (defaults filled in)
        object.__setattr__(self, "slam", with_defaults_for(self.slam, self.algorithm))

    def to_json(self) -> dict[str, Any]:
        """Plain JSON data (`from_json` reads it back to an equal object)."""
        return to_dict(self)

    @classmethod
    def from_json(cls, data: dict[str, Any]) -> RunParams:
        """Strictly validated: unknown keys, wrong types and bad values raise InputError.

        `explore` may be nested (`{"doors": {"door_align": true}}`, as `to_json` writes it) or
        flat, as runs stored before the groups hold it (`{"door_align": true}`; see
        `worker.explore.params.nest_flat`). A stored `explore.costmap.footprint_half_m`
        (every stored run has one) is accepted when it is half of `sim.footprint`, the value
        it is derived from.
        """
        return from_dict(cls, _without_derived(_nested(data)))


def _nested(data: Any) -> Any:
    """`data` with a flat `explore` mapping (runs stored before the groups) nested."""
    explore = data.get("explore") if isinstance(data, dict) else None
    nested = nest_flat(explore)
    return data if nested is explore else {**data, "explore": nested}


def _without_derived(data: Any) -> Any:
    """`data` without `explore.costmap.footprint_half_m`, once checked against
    `sim.footprint`."""
    explore = data.get("explore") if isinstance(data, dict) else None
    costmap = explore.get("costmap") if isinstance(explore, dict) else None
    if not (isinstance(costmap, dict) and "footprint_half_m" in costmap):
        return data
    sim = data.get("sim")
    side = sim.get("footprint", FOOTPRINT_M) if isinstance(sim, dict) else FOOTPRINT_M
    half = costmap["footprint_half_m"]
    numbers = all(isinstance(v, int | float) and not isinstance(v, bool) for v in (side, half))
    if numbers and half != 0.5 * side or not numbers and isinstance(side, int | float):
        raise InputError(
            f"explore.costmap.footprint_half_m ({half!r}) follows from sim.footprint "
            f"({side!r}): set the robot's size with sim.footprint [m] alone"
        )
    data = copy.copy(data)
    costmap = {k: v for k, v in costmap.items() if k != "footprint_half_m"}
    data["explore"] = {**explore, "costmap": costmap}
    return data


def run_params_schema() -> dict[str, Any]:
    """JSON Schema of RunParams with every key optional (absent keys keep their defaults), its
    sub-objects written in place (no `$ref`), and the derived keys left out."""
    schema = adapter(RunParams).json_schema()
    defs = schema.pop("$defs", {})

    def inline(node: Any) -> Any:
        if isinstance(node, dict):
            if "$ref" in node:
                return inline(defs[node["$ref"].rsplit("/", 1)[1]])
            return {k: inline(v) for k, v in node.items()}
        if isinstance(node, list):
            return [inline(v) for v in node]
        return node

    out = inline(schema)
    explore = out["properties"]["explore"]["properties"]
    explore["costmap"]["properties"].pop("footprint_half_m", None)
    return out
