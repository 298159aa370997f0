"""The sample-order rule of worker.evaluate.clock, on hand-made clocks."""

from __future__ import annotations

import numpy as np
import pytest

from worker.evaluate.clock import DEFAULT_PERIOD_S, clock_order


def test_a_clean_clock_is_kept_as_it_is():
    t = np.array([0.0, 0.1, 0.25, 0.3])
    order = clock_order(t, np.arange(4.0))
    assert order.index.tolist() == [0, 1, 2, 3]
    assert order.t.tolist() == t.tolist()
    assert (order.duplicates, order.out_of_order, order.degenerate) == (0, 0, False)
    assert order.notes("scans") == []


def test_steps_back_are_sorted_stably_and_counted():
    # 0.20 and 0.19 came after 0.21: two samples out of order; the two 0.3 keep file order
    t = np.array([0.1, 0.21, 0.20, 0.19, 0.3, 0.3, 0.4])
    content = np.arange(7.0)
    order = clock_order(t, content)
    assert order.index.tolist() == [0, 3, 2, 1, 4, 5, 6]
    assert order.out_of_order == 2 and not order.degenerate
    assert order.notes("scans") == ["2 scans out of time order: sorted (stable)"]


def test_exact_duplicates_are_dropped_and_counted():
    t = np.array([1.0, 1.0, 2.0, 2.0, 3.0])
    content = np.array([[5.0, 6.0], [5.0, 6.0], [1.0, 1.0], [1.0, 1.0], [7.0, 7.0]])
    order = clock_order(t, content)
    assert order.index.tolist() == [0, 2, 4]
    assert order.duplicates == 2
    assert order.notes("poses") == ["2 exact duplicate poses dropped"]


def test_same_time_different_content_is_not_a_duplicate():
    t = np.array([1.0, 1.0] + list(np.arange(2.0, 60.0)))
    content = np.arange(t.shape[0], dtype=float)
    order = clock_order(t, content)
    # one tie in 59 steps is under the 5 % share: the clock stays, both samples stay
    assert order.duplicates == 0 and not order.degenerate
    assert order.index.tolist()[:2] == [0, 1]


def test_a_coarse_clock_falls_back_to_the_index_clock():
    # CSAIL: six significant digits, 365 scans at 1.13486e9 and 41 at 1.13487e9
    t = np.array([1.13486e9] * 365 + [1.13487e9] * 41)
    content = np.arange(406.0)
    order = clock_order(t, content)
    assert order.degenerate
    assert order.index.tolist() == list(range(406))  # file order
    period = 1e4 / 405  # the span over the count
    np.testing.assert_allclose(np.diff(order.t), period, atol=1e-6)  # 1e9 s: ulp 2.4e-7
    assert order.t[0] == 1.13486e9
    (note,) = order.notes("scans")
    assert "cannot order the scans" in note and f"{period:.6g} s apart" in note


def test_a_clock_of_one_value_gets_the_default_period():
    order = clock_order(np.full(12, 7.0), np.arange(12.0))
    assert order.degenerate
    assert order.t.tolist() == pytest.approx([7.0 + k * DEFAULT_PERIOD_S for k in range(12)])


def test_no_samples():
    order = clock_order(np.zeros(0), np.zeros((0, 3)))
    assert order.index.shape == (0,) and not order.degenerate
