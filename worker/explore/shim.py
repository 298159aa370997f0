"""Heading shim before the DWA: turn on the spot towards a path behind, or back out if boxed in."""

from __future__ import annotations

import math

import numpy as np

from worker.evaluate.se2_scalar import wrap_fold as wrap_angle
from worker.explore import dwa_kernels as dk
from worker.explore.costmap import LocalCostmap
from worker.explore.dwa import drive
from worker.explore.params import CostmapParams, DwaParams, RecoveryParams

# added to the end cost of a motion against the way the robot is already moving: more than
# any costmap value, so it only decides when nothing else is legal
_SWITCH_PENALTY = 1000
_END_POSE_STEPS = 10  # Euler steps of a motion's end pose (_cost_after)


class HeadingShim:
    """Like nav2's RotationShimController, in front of the DWA.

    When the global path leaves the robot at more than shim_angle off its heading, the DWA's
    forward arcs (min_vel_x > 0) drive it away from the path, and among furniture into a
    spot it can neither turn in nor leave forwards. The shim turns the robot on the spot
    towards the path instead, until it faces it within shim_release; if the footprint cannot
    turn there, it moves a little (backwards first) to where it has more room, until it can.
    """

    def __init__(self, params: DwaParams, costmap: CostmapParams, recovery: RecoveryParams):
        """params: the local planner's (shim_* and the limits); costmap: the footprint's;
        recovery: the back_out_* motions that get room to turn."""
        self.params = params
        self.costmap_params = costmap
        self.recovery = recovery
        self.active = False
        self._dir = 0.0  # sign of the speed while moving to get room to turn; 0: not doing so
        self._turn = 0.0  # sign of the turn under way; 0: none
        self.n_reversals = 0  # control periods spent backing up to get room to turn

    def reset(self) -> None:
        self.active = False
        self._dir = 0.0
        self._turn = 0.0

    def command(
        self, pose: np.ndarray, w0: float, path_xy: np.ndarray | None, local: LocalCostmap
    ) -> tuple[float, float, str] | None:
        """(v, w, kind) with kind "rotate", "reverse" or "creep", or None to let the DWA drive."""
        p = self.params
        if path_xy is None or len(path_xy) < 2:
            self.active = False
            return None
        x, y, th = float(pose[0]), float(pose[1]), float(pose[2])
        if math.hypot(path_xy[-1, 0] - x, path_xy[-1, 1] - y) <= p.xy_goal_tolerance:
            self.active = False
            return None
        tx, ty = _carrot(path_xy, x, y, p.shim_lookahead)
        err = wrap_angle(math.atan2(ty - y, tx - x) - th)
        limit = p.shim_release if self.active else p.shim_angle
        if abs(err) <= limit:
            self.reset()
            return None
        self.active = True
        dt = 1.0 / p.controller_frequency
        w_mag = max(p.min_in_place_vel_theta, min(p.max_vel_theta, abs(err)))
        # the short way round as far as needed (at most sim_time), else the long way; a turn
        # under way goes on the same way while it can: a path about behind the robot, or a
        # short way blocked now and then, must not make it swing back and forth
        sign = math.copysign(1.0, err)
        first = self._turn if self._turn != 0.0 else sign
        for s in (first, -first):
            sweep = abs(err) if s == sign else 2.0 * math.pi - abs(err)
            duration = min(p.sim_time, sweep / w_mag)
            if self._legal(pose, 0.0, s * w_mag, local, duration):
                w = min(max(s * w_mag, w0 - p.acc_lim_theta * dt), w0 + p.acc_lim_theta * dt)
                self._dir = 0.0
                self._turn = s
                return 0.0, w, "rotate"
        return self._to_clearance(pose, err, local)

    def _to_clearance(self, pose: np.ndarray, err: float, local: LocalCostmap):
        """Boxed in (no turn is legal): the short legal motion, backwards or forwards, that
        leads where the costmap is lowest (farthest from obstacles) within back_out_lookahead,
        backwards on ties (the robot came from there); None when nothing is legal."""
        p, r = self.params, self.recovery
        # backing up, the rear's heading th + pi turns with w: w > 0 swings it left (ccw)
        rear_err = wrap_angle(err + math.pi)
        w_back = max(-p.max_vel_theta, min(p.max_vel_theta, r.back_out_gain * rear_err))
        w_fwd = max(-p.max_vel_theta, min(p.max_vel_theta, r.back_out_gain * err))
        v_back, v_fwd = r.back_out_speed_ratio * p.escape_vel, p.min_vel_x
        best = None
        # the exact footprint first; then one half a cell smaller: the cell test is that much
        # conservative, and a robot whose edge touches a map cell must still get away from it
        for shrink in (0.0, 0.5 * local.resolution):
            for v, w in (
                (v_back, w_back), (v_back, 0.0), (v_back, -w_back), (v_fwd, w_fwd), (v_fwd, 0.0)
            ):  # fmt: skip
                horizon = r.back_out_check_time
                if not self._legal(pose, v, w, local, horizon, padded=False, shrink=shrink):
                    continue
                # once going one way, keep going that way while it is legal (no shuffling)
                turn_back = _SWITCH_PENALTY if v * self._dir < 0 else 0
                c = self._lowest_cost_ahead(pose, v, w, local, shrink) + turn_back
                if best is None or c < best[0]:
                    best = (c, v, w)
            if best is not None:
                break
        if best is None:
            self.active = False
            self._dir = 0.0
            return None
        self._dir = math.copysign(1.0, best[1])
        self.n_reversals += best[1] < 0
        return best[1], best[2], "reverse" if best[1] < 0 else "creep"

    def _lowest_cost_ahead(
        self, pose: np.ndarray, v: float, w: float, local: LocalCostmap, shrink: float
    ) -> int:
        """The lowest costmap value at the ends of back_out_check_time steps of (v, w), as far
        as the motion stays legal, up to back_out_lookahead; the first step is legal already.
        Where the first step ends alone is myopic: between table legs a forward turn gains a
        few cells of room in half a second and ends in a slot the robot can neither turn in
        nor leave, while backing out the way it came gains more a second later."""
        r = self.recovery
        step = r.back_out_check_time
        best = _cost_after(pose, v, w, step, local)
        k = 2
        while k * step <= r.back_out_lookahead + 1e-9 and best > 0:
            if not self._legal(pose, v, w, local, k * step, padded=False, shrink=shrink):
                break
            best = min(best, _cost_after(pose, v, w, k * step, local))
            k += 1
        return best

    def _legal(
        self,
        pose,
        v: float,
        w: float,
        local: LocalCostmap,
        duration: float,
        padded: bool = True,
        shrink: float = 0.0,
    ) -> bool:
        """Driving (v, w) for `duration` [s] keeps the (padded, or shrunk by `shrink` [m])
        footprint clear. Getting room to turn is checked with the exact footprint: where the
        robot stands, it fits."""
        p, c = self.params, self.costmap_params
        half = c.footprint_half_m + (c.footprint_padding if padded else -shrink)
        return dk.motion_legal(
            float(pose[0]), float(pose[1]), float(pose[2]), v, w, duration,
            local.lethal, local.near, local.inner, float(local.origin[0]),
            float(local.origin[1]), local.resolution, half, p.angular_sim_granularity,
        )  # fmt: skip


def _carrot(path_xy: np.ndarray, x: float, y: float, lookahead: float) -> tuple[float, float]:
    """The first path point at least `lookahead` [m] from (x, y), after the point nearest it
    (the path's end if none is that far)."""
    d = np.hypot(path_xy[:, 0] - x, path_xy[:, 1] - y)
    i0 = int(np.argmin(d))
    far = np.flatnonzero(d[i0:] >= lookahead)
    k = i0 + int(far[0]) if far.size else len(path_xy) - 1
    return float(path_xy[k, 0]), float(path_xy[k, 1])


def _cost_after(pose: np.ndarray, v: float, w: float, duration: float, local: LocalCostmap) -> int:
    """Local costmap value [0, 255] where driving (v, w) for `duration` [s] ends."""
    x, y, _ = drive(float(pose[0]), float(pose[1]), float(pose[2]), v, w, duration, _END_POSE_STEPS)
    ix = int(math.floor((x - local.origin[0]) / local.resolution))
    iy = int(math.floor((y - local.origin[1]) / local.resolution))
    if not (0 <= ix < local.n and 0 <= iy < local.n):
        return 255
    return int(local.cost[iy, ix])
