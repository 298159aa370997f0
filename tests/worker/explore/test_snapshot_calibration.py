"""The snapshot stop rule on a real rbpf exploration of office_a.

tests/data/office_a_rbpf_snapshots.npz holds the SLAM map (map_saver levels) of one closed-loop
rbpf run of office_a (seed 1, the default settings, the rule itself switched off) every 300 s
of simulated time, with the coverage of the reachable free space then; made by
`benchmarks/bench_snapshot.py office_a --seeds 1 --fixture tests/data/office_a_rbpf_snapshots.npz`.
The run went on to t = 1883 s, where no frontier was left. Its coverage stopped rising at about
0.972 between t = 780 and 900 s; the rest of the run chased slivers (the thesis's reason for
the rule). Half-time is t = 940 s.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from worker.explore.params import ExploreParams
from worker.explore.stop_rules import SnapshotRule, snapshot_change

DATA = Path(__file__).resolve().parents[2] / "data" / "office_a_rbpf_snapshots.npz"


@pytest.fixture(scope="module")
def run():
    z = np.load(DATA)
    maps = [z[f"map{i}"] for i in range(len(z["t"]))]
    meta = json.loads(str(z["meta"]))
    return z["t"], z["coverage"], z["origin"], float(z["resolution"]), maps, meta


def _fires(run, **rule_kw) -> list[float]:
    """The snapshot times at which a rule with these settings says the map is unchanged."""
    t, _, origin, res, maps, _ = run
    p = ExploreParams()
    kw = {"measure": p.stop.snapshot_measure, "change": p.stop.snapshot_change,
          "tolerance": p.stop.snapshot_tolerance} | rule_kw  # fmt: skip
    rule = SnapshotRule(p.stop.snapshot_period, p.stop.snapshot_mse, **kw)
    fired = []
    for ti, img, o in zip(t, maps, origin, strict=True):
        # the images are map_saver levels already; feed them back as probabilities
        prob = np.where(img == 205, np.nan, np.where(img == 0, 1.0, 0.0)).astype(np.float32)
        if rule.check(float(ti), prob, o, res, 0.5):
            fired.append(float(ti))
    return fired


def test_the_data_is_a_finished_exploration_snapshot_every_period(run):
    t, cov, _, _, _, meta = run
    assert meta["end_reason"] == "no_frontier" and meta["end_t"] > 1800
    np.testing.assert_allclose(np.diff(t), ExploreParams().stop.snapshot_period)
    assert cov[t == 900][0] > 0.97 and cov[-1] - cov[t == 900][0] < 0.005  # it had levelled off


def test_the_default_rule_fires_when_the_map_has_settled_and_not_at_half_time(run):
    t, cov, _, _, _, meta = run
    fired = _fires(run)
    half = meta["end_t"] / 2
    assert fired and fired[0] > half  # not at half-time (nor before)
    assert fired[0] <= 1200  # within two periods of the coverage levelling off
    assert cov[t == fired[0]][0] >= meta["end_coverage"] - 0.002  # nothing left to see
    # and from there on, every comparison says unchanged
    assert fired == [x for x in t.tolist() if x >= fired[0]]


def test_at_half_time_the_map_still_changes_by_a_tenth(run):
    t, _, origin, res, maps, _ = run
    i = int(np.flatnonzero(t == 900)[0])
    c = snapshot_change(maps[i - 1], origin[i - 1], maps[i], origin[i], res, 1)
    assert c.share > 0.05  # the particle filter was still re-drawing parts of the map


def test_the_thesis_mse_never_fires_on_this_particle_filter_map(run):
    # e = 5 on map_saver levels: one wall cell that flips costs 254^2 over the extent
    assert _fires(run, measure="mse") == []
