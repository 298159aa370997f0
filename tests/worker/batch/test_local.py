"""run_local's bookkeeping when interrupted: every run the sink was told had started is handed
back to it (requeued), wherever in the sink's own call the interrupt landed."""

from __future__ import annotations

import time

import pytest

from worker.batch.experiment import RunSpec
from worker.batch.local import NullSink, run_local
from worker.batch.state import BatchDir


def slow_task(task, progress):
    """A task for the pool (importable: workers are spawned) that outlasts the test."""
    time.sleep(30)


def _spec(seed: int) -> RunSpec:
    return RunSpec(
        key=f"k{seed}", world_path="/nowhere.yaml", world="w", base="w", variant="no_furniture",
        slam="odometry", noise=0.0, seed=seed, params={},
    )  # fmt: skip


class InterruptedAfterCommit(NullSink):
    """A sink whose `started` does its work and is then interrupted (a SIGTERM arriving just
    after the database committed `running`, before the call returned)."""

    def __init__(self):
        self.started_keys: list[str] = []
        self.requeued: list[str] = []

    def started(self, spec: RunSpec) -> None:
        self.started_keys.append(spec.key)
        if len(self.started_keys) == 2:
            raise KeyboardInterrupt

    def interrupted(self, specs) -> None:
        self.requeued.extend(s.key for s in specs)


def test_an_interrupt_inside_the_sinks_started_call_still_requeues_that_run(tmp_path):
    sink = InterruptedAfterCommit()
    t0 = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        run_local([_spec(1), _spec(2), _spec(3)], BatchDir(tmp_path), 2, sink, lambda e: None,
                  fn=slow_task)  # fmt: skip
    assert time.monotonic() - t0 < 20  # the workers were stopped, not waited for
    assert sink.started_keys == ["k1", "k2"]
    assert sorted(sink.requeued) == ["k1", "k2"]  # k2 included: its start was committed
