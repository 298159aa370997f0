"""Pydantic bodies and answers of the API (the core uses dataclasses; this is the boundary)."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Annotated, Any
from urllib.parse import quote

from pydantic import AfterValidator, BaseModel, Field, model_validator

from backend.db.models import Job, Run, World
from worker.report.summary import RunSummary
from worker.run_params import run_params_schema
from worker.slam import registry
from worker.status import JobStatus, RunOutcome, RunStatus, WorldStatus
from worker.world.datasets import BundledWorld, Dataset

MAX_RUNS_PER_JOB = 1000
MAX_ALGORITHMS_PER_JOB = 8  # a comparison of more is unreadable, and a job's label must fit
# Ids and seeds are stored as the database's 32-bit integers (PostgreSQL `integer`): larger
# values cannot name a row or be stored, so the schema bounds them (422) instead of letting
# the database fail the query (500).
MAX_ID = 2**31 - 1
MAX_SEED = 2**31 - 1


class WorldOut(BaseModel):
    """A stored floorplan and its facts; the geometry is known once it is `ready`."""

    id: int
    name: str
    status: WorldStatus = Field(
        description="pending: being analysed; ready: usable; invalid: refused (see error)"
    )
    error: str | None = Field(default=None, description="why the world is invalid")
    resolution: float | None = Field(default=None, description="metres per pixel")
    origin: list[float] | None = Field(
        default=None, description="[x, y] of the image's lower-left corner, metres"
    )
    width_px: int | None = None
    height_px: int | None = None
    width_m: float | None = None
    height_m: float | None = None
    start_pose: list[float] | None = Field(
        default=None, description="[x, y, theta] in metres and radians"
    )
    facts: dict[str, Any]
    created_at: datetime

    @classmethod
    def of(cls, w: World) -> WorldOut:
        out = cls(
            id=w.id,
            name=w.name,
            status=w.status,
            error=w.error,
            facts=w.facts or {},
            created_at=w.created_at,
        )
        if w.status == WorldStatus.READY:
            out.resolution = w.resolution
            out.origin = [w.origin_x, w.origin_y]
            out.width_px, out.height_px = w.width_px, w.height_px
            out.width_m = w.width_px * w.resolution
            out.height_m = w.height_px * w.resolution
            out.start_pose = list(w.start_pose)
        return out


API_PREFIX = "/api/v1"  # where the routes below live (`backend.api.app` mounts them there)


class BundledWorldOut(BaseModel):
    """A world of a bundled data set: its facts as `load_world` gives them."""

    name: str = Field(description="its file's path in the data set's folder, without suffix")
    source_format: str = Field(description="yaml (map_server) or stage (.world)")
    resolution: float = Field(description="metres per pixel")
    origin: list[float] = Field(description="[x, y] of the image's lower-left corner, metres")
    width_px: int
    height_px: int
    width_m: float
    height_m: float
    start_pose: list[float] = Field(description="[x, y, theta] in metres and radians")
    facts: dict[str, Any]
    image_url: str = Field(description="its picture (add ?max_px=N for a thumbnail)")
    import_url: str = Field(description="POST: make it a world of yours (201, or 200 if it is)")

    @classmethod
    def of(cls, dataset: str, w: BundledWorld) -> BundledWorldOut:
        base = f"{API_PREFIX}/datasets/{quote(dataset)}/worlds/{quote(w.name)}"
        return cls(
            name=w.name,
            source_format=w.source_format,
            resolution=w.facts.resolution,
            origin=list(w.origin),
            width_px=w.facts.width_px,
            height_px=w.facts.height_px,
            width_m=w.facts.width_m,
            height_m=w.facts.height_m,
            start_pose=list(w.start_pose),
            facts=w.facts_dict(),
            image_url=f"{base}/image",
            import_url=f"{base}/import",
        )


class DatasetOut(BaseModel):
    """A data set bundled with mapqual (a folder under worlds/) and its worlds."""

    name: str = Field(description="the folder's name")
    title: str
    licence: str | None = Field(description="the licence in a few words")
    licence_file: str | None = Field(description="the file of the data set with its licence")
    licence_url: str | None = Field(description="that file's text")
    worlds: list[BundledWorldOut]
    problems: list[str] = Field(description="files of the data set that did not load")

    @classmethod
    def of(cls, d: Dataset) -> DatasetOut:
        return cls(
            name=d.name,
            title=d.title,
            licence=d.licence,
            licence_file=d.licence_file,
            licence_url=(
                f"{API_PREFIX}/datasets/{quote(d.name)}/licence" if d.licence_file else None
            ),
            worlds=[BundledWorldOut.of(d.name, w) for w in d.worlds],
            problems=list(d.problems),
        )


def _run_params_schema(schema: dict[str, Any]) -> None:
    """The field's schema becomes RunParams' (the field keeps its own description)."""
    params = run_params_schema()
    params.pop("title")
    params.pop("description")
    schema.update(params)


# A registered SLAM algorithm (worker.slam.registry): an enum in OpenAPI, checked on input.
SlamName = Annotated[
    str, AfterValidator(registry.check_name), Field(json_schema_extra=registry.add_enum)
]
# A job's parameter overrides: documented by RunParams' own JSON Schema (every key optional),
# made when OpenAPI is; validated with the defaults merged in, by RunParams itself (InputError
# -> 400 naming the key).
RunParamsOverrides = Annotated[dict[str, Any], Field(json_schema_extra=_run_params_schema)]


class JobIn(BaseModel):
    """A job: `runs` (a count, seeds 1..runs) or `seeds` (a list), and optional overrides."""

    model_config = {"extra": "forbid"}

    world_id: int = Field(ge=1, le=MAX_ID)
    runs: int | None = Field(default=None, ge=1, le=MAX_RUNS_PER_JOB)
    seeds: list[Annotated[int, Field(ge=0, le=MAX_SEED)]] | None = Field(
        default=None, min_length=1, max_length=MAX_RUNS_PER_JOB
    )
    slam: SlamName | None = None
    algorithms: list[SlamName] | None = Field(
        default=None, min_length=2, max_length=MAX_ALGORITHMS_PER_JOB,
        description="Several SLAM algorithms, each run on every seed with the same overrides: "
        "a job that compares them (give `slam` or `algorithms`, not both).",
    )  # fmt: skip
    params: RunParamsOverrides = Field(
        default_factory=dict,
        description="Overrides by section: sim, slam, explore, eval (see RunParams); keys left "
        "out keep their defaults.",
    )

    @model_validator(mode="after")
    def _runs_or_seeds(self) -> JobIn:
        if (self.runs is None) == (self.seeds is None):
            raise ValueError("give exactly one of `runs` (a count) and `seeds` (a list)")
        if self.seeds is not None and len(set(self.seeds)) != len(self.seeds):
            raise ValueError("`seeds` has duplicates")
        if self.algorithms is not None:
            if self.slam is not None:
                raise ValueError("give `slam` (one algorithm) or `algorithms`, not both")
            if len(set(self.algorithms)) != len(self.algorithms):
                raise ValueError("`algorithms` has duplicates")
            if len(self.algorithms) * len(self.seed_list()) > MAX_RUNS_PER_JOB:
                raise ValueError(f"a job has at most {MAX_RUNS_PER_JOB} runs (algorithms x seeds)")
        return self

    def algorithm_list(self) -> list[str | None]:
        """The algorithms the job runs: `algorithms`, or `slam` (None: the overrides' own)."""
        return list(self.algorithms) if self.algorithms is not None else [self.slam]

    def seed_list(self) -> list[int]:
        return list(self.seeds) if self.seeds is not None else list(range(1, self.runs + 1))


class RunBrief(BaseModel):
    """A run as listed in its job."""

    id: int
    seed: int
    slam: str | None = Field(default=None, description="its algorithm (a job may compare several)")
    status: RunStatus
    outcome: RunOutcome | None
    reason: str | None
    coverage: float | None
    b_mean_t: float | None
    b_mean_r: float | None
    progress: dict[str, Any]

    @classmethod
    def of(cls, r: Run) -> RunBrief:
        return cls(
            id=r.id,
            seed=r.seed,
            slam=getattr(r, "slam", None),
            status=r.status,
            outcome=r.outcome,
            reason=r.reason,
            coverage=r.coverage,
            b_mean_t=r.b_mean_t,
            b_mean_r=r.b_mean_r,
            progress=r.progress or {},
        )


class JobOut(BaseModel):
    """A job with its runs."""

    id: int
    world_id: int
    status: JobStatus
    slam: str
    params: dict[str, Any]
    created_at: datetime
    updated_at: datetime
    runs: list[RunBrief]

    @classmethod
    def of(cls, j: Job, runs: Sequence[Run] | None = None) -> JobOut:
        """From a Job, or from any object with its attributes (a Row) and its `runs`."""
        return cls(
            id=j.id,
            world_id=j.world_id,
            status=j.status,
            slam=j.slam,
            params=j.params,
            created_at=j.created_at,
            updated_at=j.updated_at,
            runs=[RunBrief.of(r) for r in (j.runs if runs is None else runs)],
        )


class JobPage(BaseModel):
    """One page of jobs, newest first."""

    items: list[JobOut]
    total: int
    limit: int
    offset: int


class RunOut(RunBrief):
    """A run with its full summary (the report's summary.json) once done."""

    job_id: int
    world_id: int
    slam: str
    params: dict[str, Any]
    metrics: dict[str, Any]
    summary: RunSummary | None  # null until the run is done
    error: str | None
    sim_time: float | None
    wall_time: float | None
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None

    @classmethod
    def of(cls, r: Run) -> RunOut:
        brief = RunBrief.of(r).model_dump(exclude={"slam"})
        return cls(
            **brief,
            job_id=r.job_id,
            world_id=r.world_id,
            slam=r.slam,
            params=r.params,
            metrics=r.metrics or {},
            summary=RunSummary.load(r.summary),
            error=r.error,
            sim_time=r.sim_time,
            wall_time=r.wall_time,
            created_at=r.created_at,
            started_at=r.started_at,
            finished_at=r.finished_at,
        )
