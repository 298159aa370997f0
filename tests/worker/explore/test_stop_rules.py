"""The thesis's snapshot stop rule: map images compared by mean squared error (hand-derived)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.worker.explore.test_loop import _dead_end_world, _run
from worker.explore.stop_rules import SnapshotRule, map_image, snapshot_mse


def test_map_image_uses_map_savers_grey_levels():
    prob = np.array([[np.nan, 0.1], [0.3, 0.25]], dtype=np.float32)
    np.testing.assert_array_equal(map_image(prob, 0.25), [[205, 254], [0, 254]])


def test_snapshot_mse_of_two_images_on_one_extent():
    a = np.array([[0, 254], [205, 205]], dtype=np.uint8)
    b = np.array([[254, 254], [205, 205]], dtype=np.uint8)
    # one pixel of four went from occupied to free: 254^2 / 4
    assert snapshot_mse(a, (0.0, 0.0), b, (0.0, 0.0), 0.05) == 254**2 / 4


def test_a_grown_map_counts_its_new_pixels_against_unknown():
    a = np.array([[254]], dtype=np.uint8)
    right = np.array([[254, 0]], dtype=np.uint8)  # grew by one occupied pixel to the right
    assert snapshot_mse(a, (0.0, 0.0), right, (0.0, 0.0), 0.05) == 205**2 / 2
    left = np.array([[0, 254]], dtype=np.uint8)  # the same pixel on the left: origin moved
    assert snapshot_mse(a, (0.0, 0.0), left, (-0.05, 0.0), 0.05) == 205**2 / 2
    # placed at the old origin instead: 254 -> 0 and unknown -> 254
    assert snapshot_mse(a, (0.0, 0.0), left, (0.0, 0.0), 0.05) == (254**2 + 49**2) / 2


def test_rule_takes_a_snapshot_every_period_and_fires_on_a_small_change():
    rule = SnapshotRule(period=300.0, mse=5.0)
    prob = np.full((10, 10), 0.1, dtype=np.float32)
    assert not rule.due(299.9) and rule.due(300.0)
    assert not rule.check(300.0, prob, (0.0, 0.0), 0.05, 0.25)  # the first: nothing to compare
    assert not rule.due(599.9) and rule.due(600.0)
    changed = prob.copy()
    changed[0, 0] = 0.9  # 254^2 / 100 = 645 >= 5
    assert not rule.check(600.0, changed, (0.0, 0.0), 0.05, 0.25)
    assert rule.last_mse == pytest.approx(254**2 / 100)
    assert rule.check(900.0, changed, (0.0, 0.0), 0.05, 0.25)  # unchanged: 0 < 5
    assert rule.last_mse == 0.0


def test_exploration_ends_completed_when_the_rule_fires():
    # a threshold no pair of snapshots can miss: the run ends at the second snapshot
    result, _ = _run(_dead_end_world(), snapshot_period=3.0, snapshot_mse=1e9)
    assert result.outcome == "completed" and result.reason == "map_unchanged"
    assert abs(result.t[-1] - 6.0) < 0.15
    assert "MSE" in result.stop_detail
