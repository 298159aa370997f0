"""Celery in one place: the worker's app and the API's producer read one set of names and the
settings' limits; the task the producer sends by name is the one the worker registers."""

from __future__ import annotations

import importlib.metadata
import tomllib
from pathlib import Path

from backend.core.config import Settings
from worker.celery_conf import QUEUE, RUN_TASK, TaskLimits, producer_conf, worker_conf


def test_the_worker_app_takes_its_limits_and_broker_from_the_settings(monkeypatch):
    monkeypatch.setenv("MAPQUAL_TASK_SOFT_TIME_LIMIT", "100")
    monkeypatch.setenv("MAPQUAL_TASK_TIME_LIMIT", "130")
    monkeypatch.setenv("MAPQUAL_VISIBILITY_TIMEOUT", "40")
    settings = Settings(REDIS_URL="redis://example:6380/4")
    conf = worker_conf(settings.redis_url, settings.task_limits())
    assert conf["broker_url"] == "redis://example:6380/4"
    assert (conf["task_soft_time_limit"], conf["task_time_limit"]) == (100, 130)
    opts = conf["broker_transport_options"]
    # 40 s: restore every 10 s (min(10, 40 // 4)), the sweep mutex for 20 s (40 // 2)
    assert (opts["visibility_timeout"], opts["unacked_restore_interval"]) == (40, 10)
    assert opts["unacked_mutex_expire"] == 20


def test_the_visibility_timeout_defaults_to_the_hard_limit_and_five_minutes():
    assert TaskLimits(soft_s=10, hard_s=20).visibility_timeout_s == 320
    assert Settings().task_limits() == TaskLimits(7200, 7500, None)


def test_producer_and_worker_speak_the_same_wire_on_the_same_queue():
    w, p = worker_conf("redis://x/0", TaskLimits()), producer_conf("redis://x/0")
    for key in ("task_serializer", "accept_content", "task_default_queue"):
        assert w[key] == p[key]
    assert p["task_default_queue"] == QUEUE == "mapqual"
    assert p["broker_connection_retry"] is False  # the API answers 503 instead of waiting


def test_the_worker_registers_the_task_the_api_sends():
    from backend.services.worker_host import install
    from worker.tasks import run_task

    app = install()
    assert run_task.name == RUN_TASK
    assert RUN_TASK in app.tasks
    assert app.conf.task_default_queue == QUEUE and app.conf.worker_prefetch_multiplier == 1


def test_runs_record_the_installed_version_of_mapqual():
    from worker.pipeline import _versions

    pyproject = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    assert _versions()["mapqual"] == pyproject["project"]["version"]
    assert _versions()["mapqual"] == importlib.metadata.version("mapqual")
