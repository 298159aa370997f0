"""A local batch through the one run service, on a real SQLite database with the real
pipeline: each worker process claims its run, writes the report into OUT and stores the
result; the parent records what was stored, fails a run whose world would not load, and on
resume does not run again a run the database holds as done."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from backend.core.config import Settings
from backend.db.migrate import upgrade
from backend.db.models import Run
from backend.db.session import session_scope
from backend.services.batch import DbBatch
from backend.store.lifecycle import history
from worker.batch.experiment import RunSpec
from worker.batch.local import run_local
from worker.batch.state import BatchDir
from worker.run_params import RunParams
from worker.world.loader import load_world


@pytest.fixture
def setup(tmp_path):
    img = np.full((120, 200), 255, np.uint8)
    img[[0, -1], :] = img[:, [0, -1]] = img[:, 100] = 0
    img[50:70, 100] = 255
    Image.fromarray(img).save(tmp_path / "rooms.png")
    (tmp_path / "rooms.yaml").write_text("image: rooms.png\nresolution: 0.05\n")
    url = f"sqlite:///{tmp_path / 'm.db'}"
    upgrade(url)
    settings = Settings(DATABASE_URL=url, MAPQUAL_RUNS_DIR=str(tmp_path / "runs"))
    return tmp_path, settings


def _specs(folder: Path, seeds) -> list[RunSpec]:
    params = RunParams.from_json({"algorithm": "odometry", "explore": {"time_limit": 30.0}})
    path = str((folder / "rooms.yaml").resolve())
    return [
        RunSpec(
            key=f"rooms-s{seed}",
            world_path=path,
            world="rooms",
            base="rooms",
            variant="no_furniture",
            slam="odometry",
            noise=0.0,
            seed=seed,
            params=params.to_json(),
        )  # fmt: skip
        for seed in seeds
    ]


def _batch(settings, folder: Path, specs) -> tuple[DbBatch, BatchDir]:
    worlds = {specs[0].world_path: load_world(Path(specs[0].world_path))}
    return DbBatch(settings, "b1", specs, worlds), BatchDir(folder / "out")


def test_each_run_is_stored_by_its_worker_process_and_recorded_as_stored(setup):
    folder, settings = setup
    specs = _specs(folder, [1, 2])
    db, bdir = _batch(settings, folder, specs)
    run_local(specs, bdir, 1, db, lambda e: None, fn=db.pool_run())
    records = bdir.load_records(s.key for s in specs)
    with session_scope(settings.database_url) as s:
        for spec in specs:
            run, rec = s.get_one(Run, db.run_ids[spec.key]), records[spec.key]
            assert (run.status, run.attempts, run.seed) == ("done", 1, spec.seed)
            assert run.report_dir == rec["report_dir"] == str(bdir.run_dir(spec.key).resolve())
            assert rec["summary"].to_dict() == run.summary and rec["run_id"] == run.id
            assert [e.to_status for e in history(s, run.id)] == ["running", "done"]
            files = {p.name for p in bdir.run_dir(spec.key).iterdir()}
            assert {"summary.json", "relations_B.txt", "est.tum"} <= files
            assert not files & {"report.zip", "sim.log", "sim.log.gz"}  # OUT as it was
        assert len({db.job_ids[spec.key] for spec in specs}) == 1  # seeds of one job
    assert not (folder / "runs").exists()  # nothing in the service's runs folder


def test_a_world_that_does_not_load_fails_its_run_in_the_database(setup):
    folder, settings = setup
    specs = _specs(folder, [1])
    db, bdir = _batch(settings, folder, specs)
    (folder / "rooms.yaml").unlink()  # the worker process cannot load it any more
    run_local(specs, bdir, 1, db, lambda e: None, fn=db.pool_run())
    rec = bdir.load_records(["rooms-s1"])["rooms-s1"]
    with session_scope(settings.database_url) as s:
        run = s.get_one(Run, db.run_ids["rooms-s1"])
        assert (run.status, rec["status"]) == ("failed", "error")
        assert run.error == rec["error"] and "rooms.yaml" in run.error
        assert [e.to_status for e in history(s, run.id)] == ["failed"]


def test_a_run_stored_before_its_record_was_written_is_not_run_again(setup):
    folder, settings = setup
    specs = _specs(folder, [1])
    db, bdir = _batch(settings, folder, specs)
    run_local(specs, bdir, 1, db, lambda e: None, fn=db.pool_run())
    record = bdir.run_dir("rooms-s1") / "record.json"
    record.unlink()  # the batch was killed between the commit and the record
    again, _ = _batch(settings, folder, specs)  # the same jobs, found by their keys
    assert again.run_ids == db.run_ids
    run_local(specs, bdir, 1, again, lambda e: None, fn=again.pool_run())
    rec = bdir.load_records(["rooms-s1"])["rooms-s1"]
    with session_scope(settings.database_url) as s:
        run = s.get_one(Run, db.run_ids["rooms-s1"])
        assert (run.status, run.attempts) == ("done", 1)  # stored once
        assert [e.to_status for e in history(s, run.id)] == ["running", "done"]
    assert (
        rec["status"] == "done"
        and rec["summary"].to_dict()["relations"] == run.summary["relations"]
    )
    assert (bdir.run_dir("rooms-s1") / "summary.json").is_file()  # its files written again
