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
from worker.explore.flat_params import nest_flat
from worker.explore.params import ExploreParams
from worker.param_io import adapter, from_dict, to_dict
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
    costmap.footprint_half_m follows from it (it is stored, for the record, but cannot be set
    on its own): `from_json` fills it in, and a RunParams built in Python with another robot
    size is given `ExploreParams.with_footprint(sim.footprint)`.
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
        half = self.explore.costmap.footprint_half_m
        if half != 0.5 * self.sim.footprint:
            raise InputError(_footprint_message(half, self.sim.footprint))
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
        return from_dict(cls, _with_derived(_nested(data)))


def _nested(data: Any) -> Any:
    """`data` with a flat `explore` mapping (runs stored before the groups) nested."""
    explore = data.get("explore") if isinstance(data, dict) else None
    nested = nest_flat(explore)
    return data if nested is explore else {**data, "explore": nested}


def _footprint_message(half: Any, side: Any) -> str:
    return (
        f"explore.costmap.footprint_half_m ({half!r}) follows from sim.footprint ({side!r}): "
        "set the robot's size with sim.footprint [m] alone"
    )


def _with_derived(data: Any) -> Any:
    """`data` with `explore.costmap.footprint_half_m` set to half of `sim.footprint` (a stored
    one, every stored run has one, is checked against it first). Left as is when the mapping
    or the footprint is malformed: the validation names that key."""
    if not isinstance(data, dict):
        return data
    explore, sim = data.get("explore", {}), data.get("sim", {})
    costmap = explore.get("costmap", {}) if isinstance(explore, dict) else None
    side = sim.get("footprint", FOOTPRINT_M) if isinstance(sim, dict) else None
    if not (isinstance(costmap, dict) and _is_number(side)):
        return data
    half = costmap.get("footprint_half_m", 0.5 * side)
    if not _is_number(half) or half != 0.5 * side:
        raise InputError(_footprint_message(half, side))
    data = copy.copy(data)
    data["explore"] = {**explore, "costmap": {**costmap, "footprint_half_m": 0.5 * side}}
    return data


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


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
