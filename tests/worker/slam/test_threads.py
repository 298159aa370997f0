"""A run's scan-matching threads: the process's share of its cores (MAPQUAL_SLAM_THREADS), one
when unset, a run's own number kept; bad values are one-line input errors."""

from __future__ import annotations

import os

import pytest

from worker.errors import InputError
from worker.run_params import RunParams
from worker.slam import threads as th

CORES = len(os.sched_getaffinity(0))


def test_unset_is_one_thread_and_a_set_value_is_taken(monkeypatch):
    monkeypatch.delenv(th.ENV, raising=False)
    assert th.process_threads() == 1
    monkeypatch.setenv(th.ENV, "3")
    assert th.process_threads() == 3


@pytest.mark.parametrize("bad", ["0", "-2", "two", "1.5"])
def test_a_bad_value_is_an_input_error(monkeypatch, bad):
    monkeypatch.setenv(th.ENV, bad)
    with pytest.raises(InputError, match="MAPQUAL_SLAM_THREADS must be a whole number >= 1"):
        th.process_threads()


def test_parallel_processes_share_the_cores_and_the_callers_choice_wins(monkeypatch):
    assert th.share_for(1) == CORES
    assert th.share_for(CORES) == 1 and th.share_for(4 * CORES) == 1
    monkeypatch.delenv(th.ENV, raising=False)
    th.claim_default(1)
    assert os.environ[th.ENV] == str(CORES)
    monkeypatch.setenv(th.ENV, "1")
    th.claim_default(1)
    assert os.environ[th.ENV] == "1"


def test_a_run_at_the_default_takes_the_share_and_its_own_number_is_kept(monkeypatch):
    monkeypatch.setenv(th.ENV, "2")
    default = RunParams.from_json({"algorithm": "rbpf"})
    assert default.slam.threads == 1
    assert th.with_process_threads(default).slam.threads == 2
    own = RunParams.from_json({"algorithm": "rbpf", "slam": {"threads": 3}})
    assert th.with_process_threads(own).slam.threads == 3
    monkeypatch.setenv(th.ENV, "1")
    assert th.with_process_threads(default) is default
