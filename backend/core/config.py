"""The one pydantic-settings `Settings`: every knob comes from the environment (or `.env`)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict


class Settings(BaseSettings):
    """mapqual's settings; the embedded default needs no server of any kind."""

    model_config = SettingsConfigDict(env_file=".env", extra="ignore")

    # SQLite file in the working directory by default; PostgreSQL in deployment, e.g.
    # postgresql+psycopg://mapqual@db:5432/mapqual
    database_url: str = Field(default="sqlite:///mapqual.db", alias="DATABASE_URL")
    # Report folders of runs (`runs/<id>/`).
    runs_dir: Path = Field(default=Path("runs"), alias="MAPQUAL_RUNS_DIR")
    # The Celery broker and the live-view pub/sub.
    redis_url: str = Field(default="redis://127.0.0.1:6379/0", alias="REDIS_URL")
    # API keys are required unless this is set to "off" explicitly (embedded, single-user use);
    # the server then logs a warning at start and every request acts as the local user.
    auth: Literal["on", "off"] = Field(default="on", alias="MAPQUAL_AUTH")
    # Where `mapqual viewer` is reached from a browser (the dashboard links runs there).
    viewer_url: str = Field(default="http://127.0.0.1:8080", alias="MAPQUAL_VIEWER_URL")
    # Largest accepted upload [bytes].
    max_upload_bytes: int = Field(default=20 * 1024 * 1024, alias="MAPQUAL_MAX_UPLOAD_BYTES")


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read once."""
    return Settings()
