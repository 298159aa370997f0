"""A run's summary (summary.json) as a typed, versioned model: the one schema of its results.

Light on purpose (pydantic and the standard library only, no numpy or numba): the worker builds
it, and the API, the dashboard, the CLI, the batch tables and the viewer read it by attribute.

Versions: `schema_version` 1 is the shape summary.json has had since the first run was stored,
which carries no version key. Its persisted forms (`to_dict`, `to_json_text`: summary.json, the
database row, a batch record) therefore omit the key while the version is 1, so that they stay
byte-identical with every file written before; a later version writes it. A stored summary
without the key loads as version 1, and one of an unknown version is refused.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any, Final, Literal

from pydantic import BaseModel, ConfigDict, Field, SerializerFunctionWrapHandler, model_serializer

from worker.status import RunOutcome, RunReason

SCHEMA_VERSION: Final = 1

RelationKind = Literal["B", "A", "SM"]


class _Part(BaseModel):
    """Immutable, and no key that the schema does not name."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class ErrorStats(_Part):
    """One error axis over the evaluated relations (metres or radians); null when none was."""

    mean: float | None
    std: float | None  # population std (ddof 0)
    min: float | None
    max: float | None
    n: int  # errors the statistics are over
    mean_squared: float | None
    # [m or rad] t-based 95 % half-width of the mean over the relations (issue 17): null below
    # 2 relations, absent from summaries written before 2026-12-02 (and left out when absent,
    # so that their persisted form stays byte-identical)
    ci95: float | None = None

    @model_serializer(mode="wrap")
    def _drop_absent_ci(self, handler: SerializerFunctionWrapHandler) -> dict[str, Any]:
        out = handler(self)
        if "ci95" in out and "ci95" not in self.model_fields_set:
            del out["ci95"]
        return out


class RelationErrorsSummary(_Part):
    """One relation kind's errors, in the shape `mapqual evaluate --json` prints."""

    translation: ErrorStats  # [m]
    rotation: ErrorStats  # [rad]
    skipped: int  # relations whose poses the estimate could not provide


class AteStats(_Part):
    """One ATE axis: the root of the mean square first, then the relations' statistics."""

    rmse: float | None
    mean: float | None
    std: float | None
    min: float | None
    max: float | None
    n: int
    mean_squared: float | None


class Alignment(_Part):
    """The SE(2) transform that aligns the estimate to the ground truth in least squares."""

    x: float  # [m]
    y: float  # [m]
    theta: float  # [rad]


class AteSummary(_Part):
    """Absolute trajectory error after the rigid alignment."""

    translation: AteStats  # [m]
    rotation: AteStats  # [rad]
    alignment: Alignment
    skipped: int  # ground-truth times the estimate could not provide


class MapScoreSummary(_Part):
    """The final map against the floorplan after a rigid registration (worker.evaluate.map_score);
    ratios in [0, 1], null where there was nothing to take them over."""

    precision: float | None  # map walls within tolerance of a floorplan wall
    recall: float | None  # floorplan walls the map has seen within tolerance of a map wall
    wall_coverage: float | None  # all floorplan walls within tolerance of a map wall
    distance_m: float | None  # [m] symmetric mean nearest-neighbour distance between the walls
    distance_map_m: float | None  # [m] map walls -> floorplan walls
    distance_floorplan_m: float | None  # [m] seen floorplan walls -> map walls
    free_share: float  # reachable floorplan free space the map marks free
    tolerance_m: float  # [m]
    n_map_walls: int
    n_floorplan_walls: int
    n_floorplan_walls_seen: int
    icp_iterations: int
    icp_converged: bool
    alignment: Alignment  # T_world_map after ICP
    # the map's walls: "density" (ridge of the beams' end points), "ridge" (of the hit ratio),
    # "front" or "occupied" (worker.evaluate.map_score.MapScoreParams.walls); absent from runs
    # scored before it was recorded (ridge)
    walls: str | None = Field(default=None, exclude_if=lambda v: v is None)
    walls_sigma_m: float | None = Field(default=None, exclude_if=lambda v: v is None)  # [m]


class Collision(_Part):
    """Ground-truth time and pose of the first collision."""

    t: float  # [s]
    x: float  # [m]
    y: float  # [m]
    theta: float  # [rad]


class Goals(_Part):
    """Frontier goals: reached (or explored on the way), failed, and all that were chosen."""

    reached: int
    failed: int
    total: int
    # of the total, goals of the look-through pass (a look through a door too narrow to pass);
    # absent from runs made before the pass existed (27b16d9)
    look_through: int | None = Field(default=None, exclude_if=lambda v: v is None)
    # of the total, goals of the squeeze pass (through a door the map draws 0.5 m wide or
    # narrower, entered last); absent from runs made before the pass existed
    squeeze: int | None = Field(default=None, exclude_if=lambda v: v is None)


class Timings(_Part):
    """Simulated and wall time of the run and of its stages."""

    sim_time_s: float  # [s] simulated
    wall_time_s: float  # [s]
    explore_wall_s: float  # [s] simulation, SLAM and navigation
    evaluate_wall_s: float  # [s] relations, metric and ATE
    navigation_wall_s: float  # [s]
    real_time_factor: float | None  # simulated seconds per wall second; null for no wall time
    # absent from summaries stored before 2026-11-30, when the stages were first timed apart
    simulation_wall_s: float | None = None  # [s]
    slam_wall_s: float | None = None  # [s]


class Versions(_Part):
    """Versions of the code that made the run."""

    mapqual: str
    numpy: str
    numba: str


class RealtimeSummary(_Part):
    """A run under real-time emulation (worker.slam.realtime): what the SLAM kept up with."""

    speed: float  # the robot computer's speed against the cost model's calibration machine
    fixed_latency_s: float | None  # [s] every update's latency, when fixed instead of modelled
    scans: int  # scans the laser gave
    updates: int  # SLAM updates made
    scans_dropped: int  # scans that arrived while the SLAM was busy
    latency_mean_s: float  # [s] an update's compute time, scan to published pose and map
    latency_max_s: float  # [s]


class RunSummary(_Part):
    """summary.json: outcome and coverage at the top level, each relation kind's errors, ATE,
    timings, the run's parameters and the versions of the code."""

    schema_version: Literal[1] = Field(default=SCHEMA_VERSION, description="absent means 1")
    # what the exploration achieved; it and the reasons are worker.status's vocabulary, which
    # the stop rules, batch tables and pages read too (members are the strings stored)
    outcome: RunOutcome
    reason: RunReason | None  # why it failed; null when completed
    stop: RunReason  # the stop rule that ended the exploration
    stop_detail: str  # one human-readable line
    coverage: float  # [0, 1] reachable free area the final map marks free
    world: str
    seed: int
    # a name from the SLAM registry (not a Literal here: the registry grows, one place only)
    algorithm: str
    relations: dict[RelationKind, RelationErrorsSummary]  # none with fewer than 2 poses
    ate: AteSummary | None
    path_length_m: float  # [m] ground-truth distance travelled
    collision: Collision | None
    goals: Goals
    safety_triggers: int
    recoveries: int
    timings: Timings
    # RunParams.to_json(): its schema is RunParams's own (validated by RunParams.from_json)
    params: dict[str, Any]
    versions: Versions
    # absent from summaries stored before 2026-12-02 (issue 17): such a summary is shown (API,
    # files, database) as it was stored, without the key rather than with a null
    map_score: MapScoreSummary | None = Field(default=None, exclude_if=lambda v: v is None)
    # only under real-time emulation (issue 51); absent otherwise, as from older summaries
    realtime: RealtimeSummary | None = Field(default=None, exclude_if=lambda v: v is None)

    @classmethod
    def load(cls, data: Mapping[str, Any] | None) -> RunSummary | None:
        """A stored summary (any version this code reads); None for none (null or `{}`, what
        the database holds for a run not done)."""
        return cls.model_validate(data) if data else None

    def relation(self, kind: RelationKind = "B") -> RelationErrorsSummary | None:
        """The errors of relation `kind` if at least one relation of it was evaluated."""
        rel = self.relations.get(kind)
        return rel if rel is not None and rel.translation.n else None

    def to_dict(self) -> dict[str, Any]:
        """The persisted form: plain JSON data in summary.json's key order."""
        omit = {"schema_version"} if self.schema_version == 1 else None
        return self.model_dump(mode="python", exclude=omit)

    def to_json_text(self) -> str:
        """summary.json's text (json.dumps formatting, as every summary.json ever written)."""
        return json.dumps(self.to_dict(), indent=2) + "\n"


def summary_json_schema() -> dict[str, Any]:
    """The JSON Schema of a run's summary (what the API publishes)."""
    return RunSummary.model_json_schema()
