"""The frontier choice remembered: the same question on an unchanged map gets the last answer.

A robot with no frontier left to reach stands still and asks for a frontier every control
period (the navigator's goal layer asks as long as it has no goal, with every pass: the
blacklist retry, look-through, squeeze, closed gaps reopened). Each question that finds no
reachable goal floods everything the robot can reach, several times over: work of the size
of the explored map, ten times a second, while nothing changes. `FrontierSearch.choose` is a
pure function of the costmap's layers, the frontier cells and their look counts, the
question's lists (blacklist, avoid, spent, closed gaps), its pass and the robot's position, so
its answer can be kept until one of these changes. The robot's position enters a choice only
through its cell, except for the heading of a goal that lies on its frontier cell
(`FrontierSearch._goal`): an answer with a goal is reused only for the very same position.
"""

from __future__ import annotations

import numpy as np

_MAX_ENTRIES = 32  # questions remembered per map state (a choice asks at most about ten)


def _points_key(points) -> bytes:
    """The exact bytes of a list of points `(2,)` or an array `(K, 2)` [m] (order kept)."""
    if points is None or len(points) == 0:
        return b""
    return np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 2)).tobytes()


class ChoiceMemo:
    """Answers of `FrontierSearch.choose` for the current map state (see the module's note).

    `version` counts the changes of what a choice reads: the owner calls `changed()` whenever
    a costmap layer, the frontier cells or their look counts may have changed, which forgets
    every answer.
    """

    def __init__(self):
        self.version = 0
        self.hits = 0  # questions answered from memory (for the measurements)
        self._answers: dict[tuple, tuple[tuple[float, float], object]] = {}

    def changed(self) -> None:
        """The map state changed: forget every answer."""
        self.version += 1
        self._answers.clear()

    @staticmethod
    def question(cell, blacklist, avoid, closed_points, look_through, squeeze, spent=()) -> tuple:
        """The key of one question: the robot's cell `(ix, iy)` and everything else a choice
        reads besides the map state."""
        return (
            (int(cell[0]), int(cell[1])),
            _points_key(blacklist),
            _points_key(avoid),
            _points_key(closed_points),
            bool(look_through),
            bool(squeeze),
            _points_key(spent),
        )

    def get(self, key: tuple, robot_xy) -> tuple[bool, object]:
        """(found, answer): an answer given for `key` on this map state; one with a goal only
        for the same position `robot_xy` [m], bit for bit."""
        entry = self._answers.get(key)
        if entry is None:
            return False, None
        xy, answer = entry
        if answer is not None and xy != (float(robot_xy[0]), float(robot_xy[1])):
            return False, None
        self.hits += 1
        return True, answer

    def put(self, key: tuple, robot_xy, answer) -> None:
        """Remember `answer` (a FrontierGoal or None) to `key` asked from `robot_xy` [m]."""
        if len(self._answers) >= _MAX_ENTRIES:
            self._answers.clear()
        self._answers[key] = ((float(robot_xy[0]), float(robot_xy[1])), answer)
