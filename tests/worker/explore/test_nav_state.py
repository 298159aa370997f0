"""What the goal choice remembers across goals: blacklist retries and repeated arrivals."""

from __future__ import annotations

import numpy as np

from worker.explore.nav_state import FrontierMemory


def test_the_blacklist_is_forgotten_only_as_often_as_retries_allow():
    mem = FrontierMemory(retries=1)
    assert not mem.retry()  # nothing blacklisted: nothing to forget
    mem.blacklist.append(np.array([1.0, 2.0]))
    mem.arrived_at.append((np.zeros(2), np.ones(2)))
    assert mem.retry() and mem.blacklist == [] and mem.arrived_at == [] and mem.retries == 0
    mem.blacklist.append(np.array([1.0, 2.0]))
    assert not mem.retry() and len(mem.blacklist) == 1
    # frontier cells spent by arrivals count as given up too, and are forgotten with the rest
    mem = FrontierMemory(retries=1)
    mem.spent.append(np.array([3.0, 4.0]))
    assert mem.retry() and mem.spent == [] and mem.retries == 0


def test_a_frontier_that_stays_is_spent_after_n_arrivals_near_it():
    mem = FrontierMemory(retries=1)
    r = 0.5
    mem.arrived(np.array([0.0, 0.0]), np.array([0.5, 0.0]), r, 3)
    mem.arrived(np.array([5.0, 0.0]), np.array([5.5, 0.0]), r, 3)  # elsewhere: not counted
    mem.arrived(np.array([0.9, 0.0]), np.array([0.9, 0.5]), r, 3)  # 0.9 m <= 2 r: counted
    assert mem.spent == []
    assert [g.tolist() for g in mem.avoid()] == [[0.5, 0.0], [5.5, 0.0], [0.9, 0.5]]
    # the third arrival within 1 m of (0.1, 0): (0, 0) is 0.1 m away, (0.9, 0) 0.8 m. Its
    # cells are spent, not its cluster blacklisted (the blacklist is for goals that failed)
    mem.arrived(np.array([0.1, 0.0]), np.array([0.1, -0.5]), r, 3)
    assert [b.tolist() for b in mem.spent] == [[0.1, 0.0]] and mem.blacklist == []
    # a look-through goal's frontier goes to the look-through pass's own list
    mem.arrived(np.array([0.2, 0.0]), np.array([0.2, -0.5]), r, 3, look_through=True)
    assert [b.tolist() for b in mem.looked] == [[0.2, 0.0]] and len(mem.spent) == 1
