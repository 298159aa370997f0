"""A real finished run with its report folder and sim.log, shared by the export tests."""

from __future__ import annotations

import pytest

from tests.worker.export.runs import finished_run


@pytest.fixture(scope="session")
def run_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("run") / "report"
    return folder, finished_run(folder)
