"""The frontier to go to next: the frontier search's passes, from the plain one to the last
resorts (the blacklist's retry, the look-through pass, the squeeze pass, the closed gaps
opened again)."""

from __future__ import annotations

import numpy as np

from worker.explore.costmap import GlobalCostmap
from worker.explore.frontiers import FrontierGoal, FrontierSearch
from worker.explore.nav_state import FrontierMemory
from worker.explore.planner import ClosedGaps


class GoalChooser:
    """Asks the frontier search for a goal, pass after pass, until one is found."""

    def __init__(
        self,
        frontiers: FrontierSearch,
        closed: ClosedGaps,
        memory: FrontierMemory,
        look_through_radius: float,
        reopens: int,
    ):
        """look_through_radius [m]: FrontierParams' (0: no look-through pass); reopens: times
        the closed gaps are opened again when nothing else is left (NavigatorParams.
        closed_gap_reopens)."""
        self.frontiers = frontiers
        self.closed = closed
        self.memory = memory
        self.look_through_radius = look_through_radius
        self._reopens_left = reopens  # ClosedGaps cleared when sealed in

    def choose(self, costmap: GlobalCostmap, pose: np.ndarray) -> FrontierGoal | None:
        """The goal for the robot at `pose (3,)`, or None: no reachable frontier is left."""
        mem = self.memory
        new = self.frontiers.choose(costmap, pose[:2], mem.blacklist, mem.avoid(), spent=mem.spent)
        # before giving up on the building, give the blacklisted frontiers (and the closed
        # gaps) another chance
        if new is None and mem.retry():
            self.closed.clear()
            new = self.frontiers.choose(costmap, pose[:2], mem.blacklist)
        if new is None:
            new = self._look_through(costmap, pose)
        if new is None:
            new = self._squeeze(costmap, pose)
        if new is None and len(self.closed.points) and self._reopens_left > 0:
            # nothing left with the closed gaps closed: one of them may seal the robot in (a
            # room it entered through a gap it then failed to leave by): open them once
            self._reopens_left -= 1
            self.closed.clear()
            new = self.frontiers.choose(
                costmap, pose[:2], mem.blacklist, mem.avoid(), spent=mem.spent
            )
            if new is None:
                new = self._look_through(costmap, pose)
            if new is None:
                new = self._squeeze(costmap, pose)
        return new

    def _look_through(self, costmap: GlobalCostmap, pose: np.ndarray) -> FrontierGoal | None:
        """The last pass: a goal that looks at a frontier through a gap the robot cannot
        pass (`FrontierSearch.choose`, look_through), or None (or off)."""
        if self.look_through_radius <= 0.0:
            return None
        mem = self.memory
        return self.frontiers.choose(costmap, pose[:2], mem.looked, mem.avoid(), look_through=True)

    def _squeeze(self, costmap: GlobalCostmap, pose: np.ndarray) -> FrontierGoal | None:
        """The last pass, after the look-through pass: a frontier behind a gap only
        squeeze_margin lets through (`FrontierSearch.choose`, squeeze), or None (or off).
        Last, because a robot that slipped in through such a door may not line up with it
        again from inside, and everything still to explore elsewhere would be lost."""
        mem = self.memory
        return self.frontiers.choose(
            costmap, pose[:2], mem.blacklist, mem.avoid(), spent=mem.spent, squeeze=True
        )
