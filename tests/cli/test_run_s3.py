"""`mapqual run`, `mapqual runs show` and `mapqual score` with MAPQUAL_STORAGE=s3://...: a real
process, a real SQLite database, and a real S3 endpoint (moto's server) over HTTP."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import zipfile

import pytest

from tests.cli.test_run_cli import _png
from tests.s3server import make_bucket, raw_client, s3_server


@pytest.fixture(scope="module")
def s3env():
    with s3_server() as env:
        yield env


def _mapqual(tmp_path, env, *args):
    env = dict(os.environ, **env, DATABASE_URL=f"sqlite:///{tmp_path / 'm.db'}", COLUMNS="200")
    return subprocess.run([sys.executable, "-m", "mapqual", *args], capture_output=True,
                          text=True, env=env, cwd=tmp_path, timeout=600)  # fmt: skip


def _objects(env, bucket, prefix):
    s3 = raw_client(env)
    listed = s3.list_objects_v2(Bucket=bucket, Prefix=prefix).get("Contents", [])
    return {o["Key"][len(prefix) :]: s3.get_object(Bucket=bucket, Key=o["Key"])["Body"].read()
            for o in listed}  # fmt: skip


def test_run_show_and_score_with_s3_storage(tmp_path, s3env):
    bucket = make_bucket(s3env)
    env = {**s3env, "MAPQUAL_STORAGE": f"s3://{bucket}/lab"}
    _png(tmp_path / "rooms.png")
    run = ["run", "rooms.png", "--resolution", "0.05", "--slam", "odometry", "--seed", "4",
           "--time-limit", "40", "--json"]  # fmt: skip
    r = _mapqual(tmp_path, env, *run)
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    where = doc["report_dir"]
    assert where.startswith(f"s3://{bucket}/lab/runs/{doc['run_id']}/")
    stored = _objects(env, bucket, where.removeprefix(f"s3://{bucket}/") + "/")
    assert json.loads(stored["summary.json"])["relations"] == doc["relations"]
    with zipfile.ZipFile(io.BytesIO(stored["report.zip"])) as zf:
        assert zf.read(f"run{doc['run_id']}/gt.tum") == stored["gt.tum"]
    assert not list((tmp_path / "runs").iterdir())  # the scratch folder went after the upload

    r = _mapqual(tmp_path, env, "runs", "show", str(doc["run_id"]), "--json")
    assert r.returncode == 0, r.stderr
    shown = json.loads(r.stdout)
    assert shown["report_dir"] == where and set(shown["report_files"]) == set(stored)

    (tmp_path / "est.tum").write_bytes(stored["est.tum"])  # the run's own estimate again
    r = _mapqual(tmp_path, env, "score", str(doc["run_id"]), "--est", "est.tum", "--name",
                 "again", "--json")  # fmt: skip
    assert r.returncode == 0, r.stderr
    scored = json.loads(r.stdout)
    assert scored["report_dir"] == f"{where}/estimates/again"
    b = doc["relations"]["B"]["translation"]["mean"]
    assert scored["relations"]["B"]["translation"]["mean"] == pytest.approx(b, abs=1e-6)
    assert "estimates/again/summary.json" in _objects(env, bucket, where.split("/", 3)[3] + "/")

    # -o: the folder the user named is written on this disk, and the run kept in the bucket too
    r = _mapqual(tmp_path, env, *run, "-o", "mine")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "mine" / "summary.json").is_file()
    assert not (tmp_path / "mine" / "report.zip").exists()  # the user's folder as before
    r = _mapqual(tmp_path, env, "runs", "show", str(json.loads(r.stdout)["run_id"]), "--json")
    kept = json.loads(r.stdout)
    assert kept["report_dir"].startswith(f"s3://{bucket}/lab/runs/")
    assert {"summary.json", "report.zip", "sim.log"} <= set(kept["report_files"])


def test_an_unusable_storage_setting_is_one_line_and_exit_2(tmp_path):
    _png(tmp_path / "rooms.png")
    r = _mapqual(tmp_path, {"MAPQUAL_STORAGE": "ftp://x"}, "run", "rooms.png", "--resolution",
                 "0.05", "--time-limit", "5")  # fmt: skip
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert "MAPQUAL_STORAGE" in r.stderr and "Traceback" not in r.stderr
