"""The navigator's recovery layer (move_base's recovery behaviours): no legal command ->
clear the local costmap, replan and back out along the trail; later give the goal up."""

from __future__ import annotations

import numpy as np

from worker.explore.nav_state import NavCommand, NavState, Retrace
from worker.explore.recovery import back_out


class RecoveryLayer:
    """Part of `navigator.Navigator`: its recoveries, on the navigator's own state (params,
    pursuit, retrace, trail, local costmap, stats)."""

    def _controller_failed(self, t: float, pose: np.ndarray) -> NavCommand:
        """move_base: no legal command -> clear the local costmap and replan; later give up."""
        g = self.pursuit
        if g.ctrl_fail_since is None:
            g.ctrl_fail_since = t
        self._enter(NavState.RECOVERING)
        elapsed = t - g.ctrl_fail_since
        if elapsed >= self.params.navigator.controller_patience:
            self._give_up(t, "no legal command", pose)
        elif not self._recovered and elapsed >= self.params.recovery.recovery_delay:
            self._recovered = True
            self.stats.recoveries += 1
            self.local.clear()
            g.next_plan_t = t  # replan now
            self._start_retrace(t, pose)
        return NavCommand(0.0, 0.0, "recovering")

    def _start_retrace(self, t: float, pose: np.ndarray | None = None, target=None) -> None:
        """Recovery: back out along the way the robot came (that space was free), to
        `target` (a trail point; default `Trail.back_target`)."""
        if target is None:
            target = self.trail.back_target(None if pose is None else pose[:2])
        if target is None:
            return
        self.retrace = Retrace(target, t + self.params.recovery.retrace_time)
        self.stats.recoveries += 1
        self._enter(NavState.RETRACING)

    def _retrace(self, t: float, pose: np.ndarray) -> tuple[float, float] | None:
        """Reverse towards the retrace point; None: done (or blocked), back to the goal layer."""
        d = self.retrace.target - pose[:2]
        vw = None
        if np.hypot(*d) < self.params.recovery.retrace_tolerance or t >= self.retrace.until:
            self.trail.cut_to(self.retrace.target)
        else:
            aim = self.retrace.target
            if self.params.recovery.retrace_lookahead > 0.0:
                aim = self.trail.carrot(pose[:2], aim, self.params.recovery.retrace_lookahead)
            vw = back_out(self.params.recovery, self.params.dwa, self.local, pose, aim - pose[:2])
        if vw is None:
            self.retrace = None
            self._enter(self._goal_layer_state())
        return vw
