"""The one pydantic-settings `Settings`: every knob comes from the environment (or `.env`)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from worker.celery_conf import TaskLimits
from worker.storage import Storage


class Settings(BaseSettings):
    """mapqual's settings; the embedded default needs no server of any kind."""

    model_config = SettingsConfigDict(env_file=".env", extra="ignore")

    # SQLite file in the working directory by default; PostgreSQL in deployment, e.g.
    # postgresql+psycopg://mapqual@db:5432/mapqual
    database_url: str = Field(default="sqlite:///mapqual.db", alias="DATABASE_URL")
    # Report folders of runs (`runs/<id>/`).
    runs_dir: Path = Field(default=Path("runs"), alias="MAPQUAL_RUNS_DIR")
    # Where run artifacts go: "local" (the folder MAPQUAL_RUNS_DIR; the default) or S3-compatible
    # object storage, s3://bucket[/prefix], reached with AWS_ENDPOINT_URL, AWS_ACCESS_KEY_ID,
    # AWS_SECRET_ACCESS_KEY, AWS_REGION. Workers on other machines need S3 (docs: storage).
    storage: str = Field(default="local", alias="MAPQUAL_STORAGE")
    # The Celery broker and the live-view pub/sub.
    redis_url: str = Field(default="redis://127.0.0.1:6379/0", alias="REDIS_URL")
    # API keys are required unless this is set to "off" explicitly (embedded, single-user use);
    # the server then logs a warning at start and every request acts as the local user.
    auth: Literal["on", "off"] = Field(default="on", alias="MAPQUAL_AUTH")
    # Where `mapqual viewer` is reached from a browser (the dashboard links runs there).
    viewer_url: str = Field(default="http://127.0.0.1:8080", alias="MAPQUAL_VIEWER_URL")
    # Largest accepted request body [bytes], counted while it streams in (uploads).
    max_upload_bytes: int = Field(default=20 * 1024 * 1024, alias="MAPQUAL_MAX_UPLOAD_BYTES")
    # Largest accepted floorplan image [pixels] (25 MP: a 250 m x 250 m building at 5 cm).
    max_image_pixels: int = Field(default=25_000_000, alias="MAPQUAL_MAX_IMAGE_PIXELS")
    # Processes that analyse uploaded worlds off the request thread, per API process.
    world_workers: int = Field(default=1, ge=1, alias="MAPQUAL_WORLD_WORKERS")
    # Signs viewer tokens; when unset, a random key made once and kept in the database.
    secret_key: str | None = Field(default=None, alias="MAPQUAL_SECRET_KEY")
    # How long a viewer link stays valid [s].
    viewer_token_ttl_s: int = Field(default=3600, ge=10, alias="MAPQUAL_VIEWER_TOKEN_TTL")
    # How long a dashboard sign-in lasts [s].
    session_ttl_s: int = Field(default=12 * 3600, ge=60, alias="MAPQUAL_SESSION_TTL")
    # Dashboard cookies are Secure (sent over HTTPS only; browsers treat http://localhost as
    # secure too). Switch off only to serve the dashboard over plain HTTP on another host.
    cookie_secure: bool = Field(default=True, alias="MAPQUAL_COOKIE_SECURE")
    # Per-owner quotas, answered with 429: runs queued or running at once, simulated hours
    # they may ask for in all, worlds stored, uploads in the last 24 h.
    quota_active_runs: int = Field(default=200, ge=1, alias="MAPQUAL_QUOTA_ACTIVE_RUNS")
    quota_sim_hours: float = Field(default=100.0, gt=0, alias="MAPQUAL_QUOTA_SIM_HOURS")
    quota_worlds: int = Field(default=500, ge=1, alias="MAPQUAL_QUOTA_WORLDS")
    quota_uploads_per_day: int = Field(default=200, ge=1, alias="MAPQUAL_QUOTA_UPLOADS_PER_DAY")
    # Per-owner quotas on external estimates (POST /runs/{id}/estimates): how many are stored,
    # and their stored trajectories' bytes in all [MiB].
    quota_estimates: int = Field(default=1000, ge=1, alias="MAPQUAL_QUOTA_ESTIMATES")
    quota_estimate_mb: float = Field(default=256.0, gt=0, alias="MAPQUAL_QUOTA_ESTIMATE_MB")
    # The upload sandbox (`backend.sandbox.manager`): uploads are parsed in separate processes, at
    # most this many at once per API process (others wait for one, up to the wall time)...
    sandbox_workers: int = Field(default=2, ge=1, le=64, alias="MAPQUAL_SANDBOX_WORKERS")
    # ...each with this much address space [MiB], CPU time [s] and wall time [s]...
    sandbox_memory_mb: int = Field(default=1024, ge=256, alias="MAPQUAL_SANDBOX_MEMORY_MB")
    sandbox_cpu_s: int = Field(default=10, ge=1, alias="MAPQUAL_SANDBOX_CPU_S")
    sandbox_wall_s: float = Field(default=12.0, gt=0, alias="MAPQUAL_SANDBOX_WALL_S")
    # ...and a temporary folder of its own holding at most this much [MiB] (the upload and what
    # is unpacked from it), made under this folder (unset: the system's temporary folder).
    sandbox_temp_mb: int = Field(default=96, ge=1, alias="MAPQUAL_SANDBOX_TEMP_MB")
    sandbox_dir: Path | None = Field(default=None, alias="MAPQUAL_SANDBOX_DIR")
    # A world's analysis and its predictions (`backend.services.world_analysis`) run after the
    # upload was read, in processes of their own (`world_workers` of them) with this much address
    # space [MiB], CPU time [s] and wall time [s] each.
    analysis_memory_mb: int = Field(default=4096, ge=512, alias="MAPQUAL_ANALYSIS_MEMORY_MB")
    analysis_cpu_s: int = Field(default=120, ge=1, alias="MAPQUAL_ANALYSIS_CPU_S")
    analysis_wall_s: float = Field(default=180.0, gt=0, alias="MAPQUAL_ANALYSIS_WALL_S")
    # Bytes one upload may decompress to in all [MiB]: zip members, bag chunks, gzip.
    upload_unpacked_mb: int = Field(default=64, ge=1, alias="MAPQUAL_UPLOAD_UNPACKED_MB")
    # A running run whose attempt gave no sign of life for this long [s] may be taken over by
    # another delivery of its task (the first attempt's worker is presumed dead).
    run_lease_s: float = Field(default=60.0, gt=0, alias="MAPQUAL_RUN_LEASE")
    # A run's Celery task: soft and hard time limits [s], and the broker's visibility timeout
    # [s] (unset: the hard limit + 300 s); see `worker.celery_conf.TaskLimits`.
    task_soft_time_limit_s: int = Field(default=7200, ge=1, alias="MAPQUAL_TASK_SOFT_TIME_LIMIT")
    task_time_limit_s: int = Field(default=7500, ge=1, alias="MAPQUAL_TASK_TIME_LIMIT")
    visibility_timeout_s: int | None = Field(default=None, ge=1, alias="MAPQUAL_VISIBILITY_TIMEOUT")
    # External SLAM programs users may pick by name (slam.external.name, algorithm "external"):
    # a JSON object name -> argv, e.g. {"cartographer": ["/opt/slam/bridge", "--cfg", "c.lua"]}.
    # Only these run on the workers; a request that gives a command of its own is refused.
    external_slam: dict[str, list[str]] = Field(default_factory=dict, alias="MAPQUAL_EXTERNAL_SLAM")
    # Caps on the time-outs a run may ask its external program for [s] (slam.external.
    # start_timeout_s, step_timeout_s, close_timeout_s): a run asking for more gets a 400.
    external_start_timeout_max_s: float = Field(
        default=120.0, gt=0, alias="MAPQUAL_EXTERNAL_START_TIMEOUT_MAX"
    )
    external_step_timeout_max_s: float = Field(
        default=60.0, gt=0, alias="MAPQUAL_EXTERNAL_STEP_TIMEOUT_MAX"
    )
    external_close_timeout_max_s: float = Field(
        default=10.0, gt=0, alias="MAPQUAL_EXTERNAL_CLOSE_TIMEOUT_MAX"
    )
    # An external program's address space [MiB] and CPU time [s] (its whole run).
    external_memory_mb: int = Field(default=4096, ge=64, alias="MAPQUAL_EXTERNAL_MEMORY_MB")
    external_cpu_s: int = Field(default=7200, ge=1, alias="MAPQUAL_EXTERNAL_CPU_S")

    @field_validator("storage")
    @classmethod
    def _storage(cls, value: str) -> str:
        from worker.storage import check_setting

        return check_setting(value.strip())

    def open_storage(self) -> Storage:
        """The run artifact storage this setting names (S3 clients are made once a process)."""
        from worker.storage import open_storage

        return open_storage(self.storage, self.runs_dir)

    def task_limits(self) -> TaskLimits:
        """The run task's time limits and visibility timeout."""
        return TaskLimits(
            self.task_soft_time_limit_s, self.task_time_limit_s, self.visibility_timeout_s
        )


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read once."""
    return Settings()
