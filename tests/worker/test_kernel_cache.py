"""The kernels are compiled in a child process once per version (worker.kernel_cache): the
processes that run afterwards load every kernel of a run from numba's cache."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from worker import kernel_cache
from worker.kernel_cache import marker_name, warm_kernels

ROOT = Path(__file__).resolve().parents[2]

WARM = """
from worker.kernel_cache import warm_kernels
print("warmed" if warm_kernels({algo!r}, announce=lambda: print("child started")) else "not")
"""
RUN = """
import dataclasses
from worker.pipeline import run_one
from worker.run_params import RunParams
from worker.world.loader import load_world
world = load_world({world!r})
p = RunParams(algorithm="oracle")
p = dataclasses.replace(p, explore=dataclasses.replace(p.explore, time_limit=40.0))
r = run_one(world, p, seed=3, on_progress=lambda q: None, sim_log={log!r})
print(r.summary.outcome, len(r.exploration.t))
"""


def _python(code: str, cache: Path, **env) -> subprocess.Popen:
    full = {**os.environ, "NUMBA_CACHE_DIR": str(cache), **env}
    full.pop(kernel_cache._ENV_CHILD, None)
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(code)], env=full, cwd=ROOT,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def _cached(cache: Path) -> set[str]:
    return {str(p.relative_to(cache)) for p in cache.rglob("*") if p.suffix in (".nbi", ".nbc")}


def test_two_processes_warm_an_empty_cache_once_and_a_later_run_compiles_nothing(tmp_path):
    cache = tmp_path / "cache"
    procs = [_python(WARM.format(algo="oracle"), cache) for _ in range(2)]
    outs = [p.communicate(timeout=900) for p in procs]
    for p, (out, err) in zip(procs, outs, strict=True):
        assert p.returncode == 0, err[-2000:]
        assert out.split()[-1] == "warmed"
    # the lock: one of the two started the child, the other waited and found the marker
    assert sum("child started" in out for out, _ in outs) == 1
    assert (cache / marker_name("oracle")).exists()
    before = _cached(cache)
    assert len(before) >= 20  # the simulator's, the exploration's and the evaluation's kernels
    # a run on another plan, another seed, through the pipeline's own call: loads, compiles
    # nothing (numba writes a kernel's files when it compiles one)
    world = str(ROOT / "worlds" / "bormann" / "lab_c_scan.yaml")
    run = _python(RUN.format(world=world, log=str(tmp_path / "sim.log")), cache)
    out, err = run.communicate(timeout=600)
    assert run.returncode == 0, err[-2000:]
    assert int(out.split()[-1]) > 100
    assert _cached(cache) == before


def test_a_failing_child_leaves_no_marker_and_the_caller_goes_on(tmp_path):
    cache = tmp_path / "cache"
    proc = _python(WARM.format(algo="no_such_slam"), cache)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err[-2000:]
    assert out.split()[-1] == "not"
    assert "kernels not compiled in a child (exit 1" in err
    assert not any(p.name.startswith("warmed-") for p in cache.iterdir())


@pytest.mark.parametrize("env", [{"MAPQUAL_WARM_KERNELS": "0"}, {kernel_cache._ENV_CHILD: "1"}])
def test_switched_off_or_inside_the_child_nothing_is_started(monkeypatch, tmp_path, env):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    for k, v in env.items():
        monkeypatch.setenv(k, v)

    def no_child(*a, **k):
        raise AssertionError("a child was started")

    monkeypatch.setattr(kernel_cache.subprocess, "run", no_child)
    assert warm_kernels("rbpf") is False
    assert list(tmp_path.iterdir()) == []


def test_the_marker_follows_the_algorithm_and_a_third_party_slam_warms_the_oracle():
    assert marker_name("rbpf") != marker_name("oracle")
    assert marker_name("rbpf") == marker_name("rbpf")
    assert kernel_cache.warm_algorithm("external") == "oracle"
    assert kernel_cache.warm_algorithm("graph") == "graph"
