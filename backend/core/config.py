"""The one pydantic-settings `Settings`: every knob comes from the environment (or `.env`)."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

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


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read once."""
    return Settings()
