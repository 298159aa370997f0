"""The run service with S3 storage (moto's server over HTTP): the result's transaction stores
the attempt's s3:// location; an attempt that loses keeps nothing in the bucket; a run whose
upload is refused fails with the reason and stores nothing."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from backend.core.config import Settings
from backend.db.models import Run
from backend.db.session import session_scope
from backend.services.execute import execute_run
from backend.store.lifecycle import cancel_run
from tests.backend.test_execute import _rooms, _run, pg_url  # noqa: F401
from tests.s3server import make_bucket, raw_client, s3_server


@pytest.fixture(scope="module")
def s3env() -> Iterator[dict[str, str]]:
    with s3_server() as env:
        yield env


def _keys(env: dict[str, str], bucket: str) -> list[str]:
    listed = raw_client(env).list_objects_v2(Bucket=bucket).get("Contents", [])
    return sorted(o["Key"] for o in listed)


def _settings(url: str, tmp_path, storage: str) -> Settings:
    return Settings(DATABASE_URL=url, MAPQUAL_RUNS_DIR=str(tmp_path / "scratch"),
                    MAPQUAL_STORAGE=storage, MAPQUAL_RUN_LEASE=30.0)  # fmt: skip


def test_the_commit_stores_the_uploaded_attempts_location(pg_url, tmp_path, s3env):  # noqa: F811
    bucket = make_bucket(s3env)
    run_id = _run(pg_url, "oracle", 20.0, _rooms(2, 1))
    out = execute_run(run_id, _settings(pg_url, tmp_path, f"s3://{bucket}/p"))
    assert out.kind == "done", out
    with session_scope(pg_url) as s:
        run = s.get_one(Run, run_id)
        where, attempt = run.report_dir, run.attempt
    assert out.report_dir == where == f"s3://{bucket}/p/runs/{run_id}/{attempt}"
    keys = _keys(s3env, bucket)
    prefix = f"p/runs/{run_id}/{attempt}/"
    assert keys and all(k.startswith(prefix) for k in keys)
    assert {f"{prefix}{n}" for n in ("summary.json", "report.zip", "sim.log")} <= set(keys)
    assert list((tmp_path / "scratch").iterdir()) == []  # the worker's scratch folder went


def test_a_cancelled_attempt_leaves_nothing_in_the_bucket(pg_url, tmp_path, s3env):  # noqa: F811
    """Cancelled while it runs, noticed only by the result's compare-and-set (the progress
    goes to a callback here): the attempt uploaded its report, lost, and deleted it."""
    bucket = make_bucket(s3env)
    run_id = _run(pg_url, "oracle", 20.0, _rooms(2, 1))
    settings = _settings(pg_url, tmp_path, f"s3://{bucket}/p")
    seen: list[object] = []

    def cancel_on_first_progress(progress: object) -> None:
        if not seen:
            with session_scope(pg_url) as s:
                assert cancel_run(s, run_id)
        seen.append(progress)

    out = execute_run(run_id, settings, on_progress=cancel_on_first_progress)
    assert out.kind == "lost" and "not stored" in out.message, out
    assert _keys(s3env, bucket) == []
    with session_scope(pg_url) as s:
        assert s.get_one(Run, run_id).status == "cancelled"


def test_a_refused_upload_fails_the_run_with_the_reason(pg_url, tmp_path, s3env):  # noqa: F811
    run_id = _run(pg_url, "oracle", 10.0, _rooms(1, 1))
    out = execute_run(run_id, _settings(pg_url, tmp_path, "s3://no-such-bucket-50/p"))
    assert out.kind == "failed" and "NoSuchBucket" in out.error
    with session_scope(pg_url) as s:
        run = s.get_one(Run, run_id)
        assert run.status == "failed" and run.report_dir is None and "NoSuchBucket" in run.error
